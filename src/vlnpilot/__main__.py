"""`python -m vlnpilot ARGS`: the same command line as `vln-pilot ARGS`."""

from vlnpilot.cli import main

if __name__ == "__main__":
    main()
