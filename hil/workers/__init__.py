"""Worker processes of the commands that fan work out (a pool that ends with them)."""
