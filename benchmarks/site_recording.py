"""A recording at a real site's size, made here (issue 42; docs/guide/recordings.md, "A
site-size recording made here").

    python benchmarks/site_recording.py OUT_DIR [--hours 4] [--seed 1] [--lanes 2] [--files 60]
        [--view-m 60] [--force]

SUMO's own drivers at a four-way unsignalised priority junction (``persuasive.recordings
.site``: a major road of ``--lanes`` lanes per direction with signals 200 m upstream, a
minor road that yields; Poisson flows per arm and turn, 500 vehicles an hour per major-road
lane and arm, 300 per minor arm, 2,600 an hour entering on two lanes; cars and trucks of
drawn Krauss parameters), run headless for ``--hours`` at 0.1 s steps and written into the
new folder OUT_DIR as ``--files``
INTERACTION track files cut by time (``vehicle_tracks_000.csv`` ...), the junction's
Lanelet2 map ``site.osm`` with its right of way, SUMO's network and routes
(``site.net.xml``, ``site.rou.xml``) and ``site.json`` (seed, hours, flows, counts, SUMO's
collisions, teleports and queues, SUMO's version). The folder is written as a whole: an
interrupted run leaves nothing. The same arguments give the same files, byte for byte. Then

    persuasive recordings pairs OUT_DIR --map OUT_DIR/site.osm --out pairs.parquet

finds its pairs, with the map's rule.
"""

from __future__ import annotations

import argparse
import sys
import time

#: The script's options and the SiteParams fields they set.
OPTIONS = {"hours": "--hours", "seed": "--seed", "lanes": "--lanes", "files": "--files",
           "view_m": "--view-m"}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, not the usage block
        self.exit(2, f"{self.prog}: error: {message}\n")


def _number(option: str, text: str, kind: type):
    try:
        return kind(text)
    except ValueError:
        what = "an integer" if kind is int else "a number"
        print(f"site_recording.py: error: {option} = {text!r} is not {what}", file=sys.stderr)
        raise SystemExit(2) from None


def main(argv: list[str] | None = None) -> int:
    ap = _Parser(prog="site_recording.py", description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", metavar="OUT_DIR", help="the site's folder (written as a whole)")
    ap.add_argument("--hours", default="4", help="recorded time [h] (default 4)")
    ap.add_argument("--seed", default="1", help="SUMO's seed and the vehicle types' (default 1)")
    ap.add_argument("--lanes", default="2", help="major-road lanes per direction (default 2)")
    ap.add_argument("--files", default="60", help="recordings the time is cut into (default 60)")
    ap.add_argument("--view-m", default="60", help="the camera's view: |x|, |y| <= this [m]")
    ap.add_argument("--force", action="store_true",
                    help="replace this script's own earlier files in OUT_DIR")
    args = ap.parse_args(argv)

    from persuasive.config import ConfigError
    from persuasive.recordings.formats import RecordingError
    from persuasive.recordings.site import SiteParams, make_site

    values = {"hours": _number("--hours", args.hours, float),
              "seed": _number("--seed", args.seed, int),
              "lanes": _number("--lanes", args.lanes, int),
              "files": _number("--files", args.files, int),
              "view_m": _number("--view-m", args.view_m, float)}
    t0 = time.perf_counter()

    def progress(k: int, n: int) -> None:
        if (k + 1) % 10 == 0 or k + 1 == n:
            print(f"  {k + 1} of {n} files written ({time.perf_counter() - t0:.0f} s)",
                  flush=True)

    try:
        params = SiteParams(**values)
        result = make_site(args.out_dir, params, force=args.force, progress=progress)
    except (RecordingError, ConfigError) as exc:
        message = str(exc).splitlines()[0]
        for field, option in OPTIONS.items():
            if message.startswith(f"{field} = "):
                message = option + message[len(field):]
        message = message.replace("another --out", "another OUT_DIR")
        print(f"site_recording.py: error: {message}", file=sys.stderr)
        return 2
    d = result.to_dict()
    sumo = d["sumo"]
    queues = ", ".join(f"{e} {sumo['queue_mean_veh'][e]:.1f} / {sumo['queue_max_veh'][e]}"
                       for e in sumo["queue_mean_veh"])
    print(f"site in {args.out_dir}: {len(result.files)} files, {result.tracks:,} tracks "
          f"({result.vehicles_recorded:,} vehicles, {result.trucks_recorded} trucks), "
          f"{result.recorded_h:.2f} h recorded, {result.samples:,} rows")
    print(f"{sumo['version']}, seed {params.seed}: {result.vehicles_inserted:,} vehicles "
          f"inserted; collisions {result.collisions}, teleports {result.teleports}, "
          f"emergency braking {result.emergency_braking}")
    print(f"halting vehicles per approach, mean / largest: {queues}; waiting to be inserted: "
          f"at most {result.backlog_max}, {result.backlog_end} at the end")
    print(f"map: site.osm ({result.map_lanelets} lanelets, {result.map_right_of_way} "
          f"right-of-way elements); written in {result.wall_s:.1f} s")
    print(f"next: persuasive recordings pairs {args.out_dir} --map {args.out_dir}/site.osm "
          "--out pairs.parquet")
    return 0


if __name__ == "__main__":
    sys.exit(main())
