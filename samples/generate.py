"""Generate a synthetic painted vessel: textured OBJ + MTL + PNG and its ground truth.

Example::

    python samples/generate.py --kind amphora --vertices 20000 -o samples/data/

writes ``amphora.obj``, ``amphora.mtl``, ``amphora.png`` and ``amphora.truth.json``
(axis, pose, profile, painted circles, holes) into the output folder. See
``samples/README.md`` and :func:`potflat_synthetic.vessels.make_vessel` for every option.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    from potflat_synthetic.vessels import KINDS, PAINTINGS

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example: python samples/generate.py --kind amphora "
                                        "--vertices 20000 -o samples/data/")
    ap.add_argument("--kind", choices=KINDS, default="amphora")
    ap.add_argument("--vertices", type=int, default=20000, help="target vertex count")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--texture-size", type=int, default=1024, help="atlas side in pixels")
    ap.add_argument("--no-pose", action="store_true", help="keep the axis along +z")
    ap.add_argument("--base", action=argparse.BooleanOptionalAction, default=None,
                    help="close the foot with a flat base (default: cup only)")
    ap.add_argument("--walls", type=int, choices=(1, 2), default=None,
                    help="2 = outer and inner wall (cup, kylix)")
    ap.add_argument("--thickness", type=float, default=4.0, help="wall thickness (mm) for --walls 2")
    ap.add_argument("--handles", nargs="?", const="intersecting", default=None,
                    choices=("intersecting", "welded"),
                    help="add handles: tubes sunk into the wall (default) or welded into it")
    ap.add_argument("--holes", type=int, default=0)
    ap.add_argument("--sherd-of", default="hydria", help="parent profile of --kind sherd")
    ap.add_argument("--sherd-span", type=float, default=80.0, help="sherd width in degrees")
    ap.add_argument("--sherd-thickness", type=float, default=0.0,
                    help="0 = painted surface only; else a closed fragment this thick (mm)")
    ap.add_argument("--painting", choices=PAINTINGS, default="frieze",
                    help="frieze (default), belt or panel (black glaze elsewhere), allover")
    ap.add_argument("--shading", action="store_true",
                    help="light the texture with a smooth gradient and mild noise, like a scan")
    ap.add_argument("--ply", action="store_true", help="also write a vertex-coloured PLY")
    ap.add_argument("--name", default=None, help="output file stem (default: the kind)")
    ap.add_argument("-o", "--out", type=Path, default=Path("."), help="output folder")
    args = ap.parse_args(argv)

    from potflat.errors import PotflatError
    from potflat_synthetic.vessels import make_vessel, write_obj, write_ply_colored, write_truth

    try:
        vessel = make_vessel(
            args.kind, n_vertices=args.vertices, seed=args.seed, pose=not args.no_pose,
            texture_size=args.texture_size, base=args.base, walls=args.walls,
            thickness=args.thickness, handles=args.handles or False, holes=args.holes,
            sherd_of=args.sherd_of, sherd_span=args.sherd_span,
            sherd_thickness=args.sherd_thickness, painting=args.painting, shading=args.shading,
        )
        stem = args.name or args.kind
        obj = write_obj(vessel, args.out / f"{stem}.obj")
        write_truth(vessel, args.out / f"{stem}.truth.json")
        if args.ply:
            write_ply_colored(vessel, args.out / f"{stem}.ply")
    except PotflatError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    m = vessel.mesh
    print(f"{obj}: {len(m.vertices)} vertices, {len(m.faces)} faces, "
          f"{int(vessel.face_chart.max()) + 1} texture charts")
    return 0


if __name__ == "__main__":
    sys.exit(main())
