"""`python -m jaxrb` is the `jaxrb` command line."""

from ._cli import console_main

if __name__ == "__main__":
    console_main()
