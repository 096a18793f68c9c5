"""SUMO's own drivers as a recording: the example of docs/guide/recordings.md ("SUMO's
floating-car data"), end to end.

    python benchmarks/sumo_fcd_example.py [--out DIR] [--noise-m 0.05] [--noise-mps 0.1]

Builds the ``intersection`` network of ``persuasive sumo`` (``persuasive.envs.sumo
.build_network``), writes a route file with six vehicles on each of three routes (west-east
and east-west on the major road, south-north on the minor road, the minor road's third
vehicle a truck; one departure per route every 4 s, the routes 1.5 s apart), runs SUMO for
70 s with its floating-car output at 0.1 s (ballistic updates, seed 1), then runs

    persuasive recordings export fcd.xml --types routes.rou.xml --out tracks ...
    persuasive recordings pairs tracks --out pairs.parquet
    persuasive recordings replay pairs.parquet

and prints what they print. ``--out`` keeps the files (default: a temporary folder).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

ROUTES = (("we", "W2C C2E", 0.0), ("ew", "E2C C2W", 1.5), ("sn", "S2C C2N", 3.0))


def route_file(path: Path) -> None:
    vehicles = []
    for name, _, offset in ROUTES:
        for k in range(6):
            truck = name == "sn" and k == 2
            vehicles.append((offset + 4.0 * k, f"{name}{k}", "truck" if truck else "car",
                             name))
    lines = ['<routes>', '  <vType id="car" vClass="passenger" length="4.5" width="1.8"/>',
             '  <vType id="truck" vClass="truck" length="9.0" width="2.5" accel="1.3" '
             'decel="4.0"/>']
    lines += [f'  <route id="{name}" edges="{edges}"/>' for name, edges, _ in ROUTES]
    lines += [f'  <vehicle id="{vid}" type="{vtype}" route="{route}" depart="{t:g}" '
              'departSpeed="desired"/>' for t, vid, vtype, route in sorted(vehicles)]
    lines.append('</routes>')
    path.write_text("\n".join(lines) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="keep the files in this (new) folder")
    ap.add_argument("--noise-m", default="0.05")
    ap.add_argument("--noise-mps", default="0.1")
    args = ap.parse_args()
    from persuasive.envs.sumo import NETWORKS, build_network, sumo_binaries

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.out) if args.out else Path(tmp)
        folder.mkdir(parents=True, exist_ok=bool(not args.out))
        build_network(NETWORKS["intersection"], folder)
        route_file(folder / "routes.rou.xml")
        sumo = f"{sumo_binaries()['home']}/bin/sumo"
        subprocess.run([sumo, "--net-file", str(folder / "net.net.xml"), "--route-files",
                        str(folder / "routes.rou.xml"), "--fcd-output", str(folder / "fcd.xml"),
                        "--step-length", "0.1", "--end", "70", "--step-method.ballistic",
                        "true", "--seed", "1", "--no-step-log", "true"], check=True)
        cli = [sys.executable, "-m", "persuasive", "recordings"]
        for args_ in (["export", str(folder / "fcd.xml"), "--types",
                       str(folder / "routes.rou.xml"), "--out", str(folder / "tracks"),
                       "--noise-m", args.noise_m, "--noise-mps", args.noise_mps],
                      ["pairs", str(folder / "tracks"), "--out", str(folder / "pairs.parquet")],
                      ["replay", str(folder / "pairs.parquet")]):
            subprocess.run(cli + args_, check=True)


if __name__ == "__main__":
    main()
