"""One module per ``potflat`` sub-command."""
