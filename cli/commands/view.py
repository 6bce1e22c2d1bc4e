"""`potflat view`: a finished run's scan and flat image side by side in the browser."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from potflat_cli._errors import user_errors

HELP = """Open a finished run in the browser: on the left the whole scan in 3D with its texture, the seam, the image's edge and the painted zone's outline; on the right the flat image with deep zoom, its distortion maps, (with --relief) its relief images and the base's disc when the rollout left the base out (on its own grid, not linked). The two are linked (hover or click either), a readout gives the point's position in mm and the local length error and anisotropy, and two clicks measure a distance on the image and on the vessel.

Edit and rerun from the page: the seam through a clicked point, an angle window or an overlap dragged on the image, the painted zone with a brush; 'Rerun' runs the stages whose options changed into the run's folder, as the equivalent 'potflat run' command the page shows does (each stage's JSON records its options).

OUT is the output folder of 'potflat run' (or of 'potflat batch': the report links each scan to its view). The page is served on 127.0.0.1 only, on a free port, with a random token in its address, until Ctrl-C. Exit codes: 2 bad input, 130 stopped (Ctrl-C).

Example:  potflat view out/ amphora
"""


@user_errors
def view_command(
    out: Annotated[Path, typer.Argument(help="Output folder of potflat run or batch.", exists=True, file_okay=False)],
    name: Annotated[Optional[str], typer.Argument(help="The run to open (NAME of NAME.png) \\[default: the only "
                                                       "run in OUT; a batch's report when there are several].")] = None,
    port: Annotated[int, typer.Option("--port", min=0, max=65535, show_default=False,
                                             help="Port on 127.0.0.1 \\[default: a free one].")] = 0,
    no_browser: Annotated[bool, typer.Option("--no-browser", help="Print the address; do not open a browser.")] = False,
) -> None:
    """Open a finished run in the browser: the vessel and its flat image, linked."""
    # imported here, not at the top: 'potflat --help' stays free of Numba and SciPy
    import webbrowser

    from potflat.errors import InvalidOptionError
    from potflat.view.server import serve

    server = serve(out, port=port)
    try:
        names = list(server.runs.folders)
        if name is not None and name not in server.runs.folders:
            raise InvalidOptionError(f"{out} has no run {name!r}; give one of {', '.join(names[:10])}")
        name = name or (names[0] if len(names) == 1 else None)
        url = server.url(name)
        print(f"potflat view: {url}  (Ctrl-C to stop)", flush=True)
        server.warm([name] if name else names[:1])
        if not no_browser:
            webbrowser.open(url)
        server.serve_forever(poll_interval=0.2)
    finally:
        server.server_close()


view_command.__doc__ = HELP
