from potflat_cli.main import app

app(prog_name="potflat")
