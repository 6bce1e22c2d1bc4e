"""``python -m potflat_cli``: the ``potflat`` command."""
from potflat_cli._start import main

if __name__ == "__main__":
    main()
