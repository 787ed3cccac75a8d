"""The two ways an image fails (kept import-light: the CLI catches them without loading
the emulator)."""


class ImageError(Exception):
    """The image cannot run in the harness (not an ARM ELF, no entry, ...); ``str`` is one
    line naming the file and the reason. A usage error: exit 2."""


class ImageFault(Exception):
    """The image broke the firmware interface while running (bad address, hard fault,
    unaligned access, no return, overrun); ``str`` is one line naming the step, the
    address and the symbol where known. The run fails: exit 1."""
