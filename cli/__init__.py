"""The ``potflat`` command line (installed as the package ``potflat_cli``)."""
