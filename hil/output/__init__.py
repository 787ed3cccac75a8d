"""What people read: plain-text tables for the terminal and figures (matplotlib)."""
