"""`python -m vlnpilot`: the same command line as `vln-pilot`."""

from vlnpilot.cli import main

if __name__ == "__main__":
    main()
