"""Figures, animations and the plot commands (``persuasive.plots``, ``persuasive._cli_plots``).

The figures are checked through their artists: every data artist carries a ``gid``, and its
data must equal the run's log and states exactly (the plot functions copy, never compute).
Crossing times are recomputed here from the states and the spec's arrival test
(``s >= -(stop_distance + 0.2 m)``), independently of the plotting code. Saved files are read
back: PNGs must hold the HV blue and the AV red, animations one frame per decision step.
"""

from __future__ import annotations

import gc
import pkgutil
import subprocess
import sys
from pathlib import Path

import imageio.v2 as iio2
import imageio.v3 as iio3
import matplotlib.image as mpimg
import numpy as np
import pytest
from matplotlib.colors import to_rgba
from matplotlib.legend import Legend
from matplotlib.patches import Circle, Polygon
from matplotlib.transforms import Bbox

import persuasive
from persuasive import plots
from persuasive._files import OutputError
from persuasive.cli import cli, main
from persuasive.config import Config, ConfigError
from persuasive.experiments import PUBLISHED, reproduce, save
from persuasive.simulation import simulate

SEED = 996
ARRIVAL_TOL_M = 0.2  # Q7, the arrival tolerance of the paper's runs


# -- fixtures -----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def lfg_run():
    return simulate(Config().with_overrides({"av.kind": "lfg"}), SEED)


@pytest.fixture(scope="module")
def mpc_run():
    return simulate(Config().with_overrides({"av.kind": "persuasive"}), SEED)


@pytest.fixture(scope="module")
def short_run():
    """A 25-step MPC run, for the animations."""
    return simulate(Config().with_overrides({"simulation.n_steps": 25}), SEED)


@pytest.fixture(scope="module")
def profile(lfg_run, mpc_run):
    return plots.profile_figure(lfg_run, mpc_run)


@pytest.fixture(scope="module")
def topview(lfg_run, mpc_run):
    return plots.topview_figure(lfg_run, mpc_run)


@pytest.fixture(scope="module")
def results_dir(tmp_path_factory):
    """A real ``reproduce table2`` results folder (2 seeds per row)."""
    folder = tmp_path_factory.mktemp("results") / "table2"
    save(reproduce("table2", seeds=2, workers=1), "table2", folder)
    return folder


@pytest.fixture(scope="module")
def summary(results_dir):
    import json

    return json.loads((results_dir / "summary.json").read_text())


# -- helpers ------------------------------------------------------------------------------------


def by_gid(container, gid):
    """The artists of ``container`` (axes or figure) with ``gid``."""
    return [a for a in container.findobj() if a.get_gid() == gid]


def one(ax, gid):
    found = by_gid(ax, gid)
    assert len(found) == 1, f"{gid}: {len(found)} artists"
    return found[0]


def expected_crossing(run, column):
    """First ``k >= 1`` with the vehicle at the crossing line, as ``k * dt``; None if never."""
    line = -(run.config.vehicle.stop_distance_m + ARRIVAL_TOL_M)
    hits = np.flatnonzero(run.states[1:, column] >= line)
    return None if hits.size == 0 else (hits[0] + 1) * run.config.simulation.dt_s


def colour_pixels(image):
    """Counts of AV-red and HV-blue pixels in an RGB(A) image with values in [0, 255]."""
    rgb = image[..., :3].astype(float)
    if rgb.max() <= 1.0:
        rgb = rgb * 255
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    red = (r > 180) & (g < 90) & (b < 90)
    blue = (b > 150) & (r < 80) & (g > 80) & (g < 160)
    return int(red.sum()), int(blue.sum())


# -- module boundaries --------------------------------------------------------------------------


def test_model_modules_and_cli_do_not_import_matplotlib():
    # Every module outside persuasive.plots (but the entry point __main__, which runs), listed
    # here: walking the package imports each subpackage, persuasive.plots included.
    names = [m.name for m in pkgutil.walk_packages(persuasive.__path__, "persuasive.")
             if m.name.split(".")[1] not in ("plots", "__main__")]
    assert "persuasive.cli" in names and "persuasive.simulation" in names
    code = (f"import sys; import {', '.join(names)}; "
            "sys.exit(any(m.split('.')[0] == 'matplotlib' for m in sys.modules))")
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


PLOTS_API = ["ANIMATION_EXTENSIONS", "AV_COLOR", "DOUBLE_COLUMN_IN", "FIGURE_EXTENSIONS",
             "HV_COLOR", "PROFILE_ROWS", "SINGLE_COLUMN_IN", "animate", "animation_frames",
             "belief_column", "case_title", "check_animation_path", "check_figure_path",
             "crossing_time", "draw_intersection", "profile_figure", "profile_single",
             "run_label", "save_figure", "snapshot_indices", "table_figure", "table_row_label",
             "topview_figure", "topview_single"]


def test_plots_package_keeps_the_public_api():
    assert set(PLOTS_API) <= set(plots.__all__)
    for name in PLOTS_API:
        value = getattr(plots, name)
        if callable(value):
            assert value.__module__.startswith("persuasive.plots."), name


# -- profile figure (Fig. 2) --------------------------------------------------------------------


def test_profile_layout(profile, lfg_run, mpc_run):
    axes = profile.axes
    assert len(axes) == 8  # 4 rows x 2 columns
    grid = np.array(axes).reshape(4, 2)
    assert "AV: LFG" in grid[0, 0].get_title() and "branch MPC" in grid[0, 1].get_title()
    assert "seed 996" in profile.get_suptitle()
    for ax in axes:  # one shared time axis over the whole run
        assert ax.get_xlim() == pytest.approx((0.0, 61 * 0.1))
    # data lines per row (+ 2 crossing markers each): the MPC AV has no role line
    counts = [[len(ax.get_lines()) for ax in row] for row in grid]
    assert counts == [[4, 3], [4, 4], [4, 4], [4, 4]]
    assert by_gid(grid[0, 1], "av-role") == []
    assert grid[0, 0].get_yticks().tolist() == [0.0, 1.0]
    assert [t.get_text() for t in grid[0, 0].get_yticklabels()] == ["F", "L"]


@pytest.mark.parametrize("column", [0, 1])
def test_profile_lines_equal_the_log(profile, lfg_run, mpc_run, column):
    run = (lfg_run, mpc_run)[column]
    log, states, n = run.log, run.states, len(run.log["step"])
    rows = np.array(profile.axes).reshape(4, 2)[:, column]
    t_states = np.arange(n + 1) * 0.1
    for who, s_col in (("hv", 3), ("av", 1)):
        speed = one(rows[2], f"{who}-speed")
        np.testing.assert_array_equal(speed.get_ydata()[:-1], log[f"{who}_v_mps"])
        assert speed.get_ydata()[-1] == states[-1, s_col]
        np.testing.assert_allclose(speed.get_xdata(), t_states, rtol=0, atol=1e-12)
        accel = one(rows[3], f"{who}-accel")
        assert accel.get_drawstyle() == "steps-post"
        np.testing.assert_array_equal(accel.get_ydata()[:-1], log[f"{who}_accel_mps2"])
        np.testing.assert_array_equal(one(rows[1], f"{who}-belief").get_xdata(), log["t_s"])
    np.testing.assert_array_equal(one(rows[1], "hv-belief").get_ydata(),
                                  log["hv_belief_other_leader"])
    av_belief = "av_belief_other_leader" if column == 0 else "av_belief_hv_leader"
    np.testing.assert_array_equal(one(rows[1], "av-belief").get_ydata(), log[av_belief])
    for who in ("hv", "av") if column == 0 else ("hv",):
        role = one(rows[0], f"{who}-role")
        np.testing.assert_array_equal(role.get_ydata()[:-1], log[f"{who}_role"] == "leader")
    # colours: HV blue, AV red
    assert one(rows[2], "hv-speed").get_color() == plots.HV_COLOR
    assert one(rows[2], "av-speed").get_color() == plots.AV_COLOR


@pytest.mark.parametrize("column", [0, 1])
def test_profile_crossing_markers(profile, lfg_run, mpc_run, column):
    run = (lfg_run, mpc_run)[column]
    rows = np.array(profile.axes).reshape(4, 2)[:, column]
    times = {who: expected_crossing(run, col) for who, col in (("av", 0), ("hv", 2))}
    # the first arrival is the outcome's idx_end (after step idx_end)
    assert min(times.values()) == pytest.approx((run.outcome.idx_end + 1) * 0.1)
    for ax in rows:
        for who, t in times.items():
            marker = one(ax, f"{who}-crossing")
            np.testing.assert_allclose(marker.get_xdata(), [t, t], rtol=0, atol=1e-12)
            assert marker.get_linestyle() == "--"
            assert marker.get_color() == {"hv": plots.HV_COLOR, "av": plots.AV_COLOR}[who]


def test_seed_996_crossings_are_the_papers_order(lfg_run, mpc_run):
    # 2-LFG: the HV leads and crosses first; with the MPC the AV persuades it and goes first.
    assert plots.crossing_time(lfg_run, "hv") < plots.crossing_time(lfg_run, "av")
    assert plots.crossing_time(mpc_run, "av") < plots.crossing_time(mpc_run, "hv")


def test_no_crossing_no_marker():
    run = simulate(Config().with_overrides({"simulation.n_steps": 8}), SEED)
    assert plots.crossing_time(run, "av") is None and plots.crossing_time(run, "hv") is None
    fig = plots.profile_single(run)
    assert len(fig.axes) == 4
    assert by_gid(fig, "av-crossing") == [] and by_gid(fig, "hv-crossing") == []
    np.testing.assert_array_equal(one(fig.axes[2], "hv-speed").get_ydata(), run.states[:, 3])


def test_profile_single_lfg_draws_both_roles(lfg_run):
    fig = plots.profile_single(lfg_run)
    assert len(fig.axes) == 4
    assert [len(ax.get_lines()) for ax in fig.axes] == [4, 4, 4, 4]
    assert "seed 996" in fig.axes[0].get_title()


# -- saving -------------------------------------------------------------------------------------


def test_saved_png_is_not_blank_and_has_both_colours(profile, tmp_path):
    path = plots.save_figure(profile, tmp_path / "profile.png", dpi=100)
    image = mpimg.imread(path)
    assert image.shape[:2] == (520, 700)  # 7.0 x 5.2 in at 100 dpi
    assert image[..., :3].std() > 0.05
    red, blue = colour_pixels(image)
    assert red > 500 and blue > 500


@pytest.mark.parametrize("ext, magic", [(".svg", b"<svg"), (".pdf", b"%PDF"), (".PNG", b"\x89PNG")])
def test_format_follows_extension(lfg_run, tmp_path, ext, magic):
    path = plots.save_figure(plots.profile_single(lfg_run), tmp_path / f"fig{ext}", dpi=50)
    head = path.read_bytes()[:400]
    assert magic in head
    if ext == ".svg":  # the gids reach the SVG
        assert b'id="hv-speed"' in path.read_bytes()


def test_unknown_extension_and_failed_write_leave_files_alone(lfg_run, tmp_path, monkeypatch):
    fig = plots.profile_single(lfg_run)
    with pytest.raises(ConfigError, match="unsupported extension '.jpg'"):
        plots.save_figure(fig, tmp_path / "fig.jpg")
    target = tmp_path / "fig.png"
    target.write_bytes(b"old")

    def broken(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(fig, "savefig", broken)
    with pytest.raises(OutputError) as info:
        plots.save_figure(fig, target)
    assert str(info.value) == f"cannot write {str(target)!r}: disk full"
    assert target.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig.png"]


def _write_figure(fig, run, path):
    return plots.save_figure(fig, path, dpi=20)


def _write_animation(fig, run, path):
    return plots.animate(run, path)


WRITERS = {"figure": (_write_figure, ".png"), "animation": (_write_animation, ".mp4")}


@pytest.fixture(scope="module")
def tiny_run():
    return simulate(Config().with_overrides({"simulation.n_steps": 3}), SEED)


@pytest.mark.parametrize("kind", WRITERS)
@pytest.mark.parametrize("case, reason", [
    ("parent is a file", "is not a folder"),
    ("missing parent", "does not exist"),
    ("target is a folder", "it is a folder"),
])
def test_unwritable_targets_fail_in_one_line_and_leave_nothing(tiny_run, tmp_path, kind, case,
                                                               reason):
    write, ext = WRITERS[kind]
    (tmp_path / "file").write_bytes(b"old")
    (tmp_path / f"folder{ext}").mkdir()
    target = {"parent is a file": tmp_path / "file" / f"out{ext}",
              "missing parent": tmp_path / "missing" / f"out{ext}",
              "target is a folder": tmp_path / f"folder{ext}"}[case]
    fig = plots.profile_single(tiny_run) if kind == "figure" else None
    with pytest.raises(OutputError) as info:
        write(fig, tiny_run, target)
    message = str(info.value)
    assert "\n" not in message and repr(str(target)) in message and reason in message
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", f"folder{ext}"]
    assert (tmp_path / "file").read_bytes() == b"old"
    assert list((tmp_path / f"folder{ext}").iterdir()) == []


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux /proc")
@pytest.mark.parametrize("kind", WRITERS)
def test_target_in_a_read_only_folder_fails_in_one_line(tiny_run, kind):
    write, ext = WRITERS[kind]
    target = Path(f"/proc/persuasive-test{ext}")
    fig = plots.profile_single(tiny_run) if kind == "figure" else None
    with pytest.raises(OutputError) as info:
        write(fig, tiny_run, target)
    message = str(info.value)
    assert message.startswith(f"cannot write {str(target)!r}: ") and "\n" not in message
    assert not target.exists()


# -- top view (Fig. 3) --------------------------------------------------------------------------


def test_topview_geometry(topview, lfg_run):
    veh = lfg_run.config.vehicle
    assert len(topview.axes) == 2
    a, b = topview.axes
    assert a.get_xlim() == b.get_xlim() == a.get_ylim() == b.get_ylim()  # one square window
    for ax in (a, b):
        assert ax.get_aspect() == 1.0
        road_av, road_hv = one(ax, "road-av").get_xy(), one(ax, "road-hv").get_xy()
        # each road is a strip lane_width_m wide around its vehicle's path
        assert np.ptp(road_av[:, 1]) == np.ptp(road_hv[:, 0]) == veh.lane_width_m == 4.0
        assert set(road_av[:, 1]) == {-2.0, 2.0} and set(road_hv[:, 0]) == {-2.0, 2.0}
        np.testing.assert_array_equal(one(ax, "av-crossing-line").get_xdata(), [-6.5, -6.5])
        np.testing.assert_array_equal(one(ax, "hv-crossing-line").get_ydata(), [-6.5, -6.5])
        circle = one(ax, "safety-circle")
        assert isinstance(circle, Circle) and circle.get_radius() == veh.min_dist_m == 7.5
        assert circle.center == (0.0, 0.0)


@pytest.mark.parametrize("column", [0, 1])
def test_topview_snapshots_follow_the_states(topview, lfg_run, mpc_run, column):
    run, ax = (lfg_run, mpc_run)[column], topview.axes[column]
    idx = np.arange(0, 62, 10)  # every 1 s: states 0, 10, ..., 60
    for who, col in (("av", 0), ("hv", 2)):
        snaps = by_gid(ax, f"{who}-snapshot")
        assert len(snaps) == idx.size and all(isinstance(r, Polygon) for r in snaps)
        s = run.states[idx, col]
        corners = [r.get_xy()[:4] for r in snaps]
        centres = [c.mean(axis=0) for c in corners]
        # corners are centre +- half-extents: exact to rounding of the positions
        extents = {(round(float(np.ptp(c[:, 0])), 9), round(float(np.ptp(c[:, 1])), 9))
                   for c in corners}
        if who == "av":  # along x at (s, 0), 5 m long and 2.5 m wide
            np.testing.assert_allclose(centres, np.c_[s, np.zeros_like(s)], atol=1e-12)
            assert extents == {(5.0, 2.5)}
        else:  # along y at (0, s)
            np.testing.assert_allclose(centres, np.c_[np.zeros_like(s), s], atol=1e-12)
            assert extents == {(2.5, 5.0)}
        alphas = [r.get_facecolor()[3] for r in snaps]
        assert np.all(np.diff(alphas) > 0)  # older snapshots fainter
        path = one(ax, f"{who}-path")
        np.testing.assert_array_equal(path.get_xdata() if who == "av" else path.get_ydata(),
                                      run.states[:, col])
        labels = [t.get_text() for t in by_gid(ax, f"{who}-time-label")]
        assert labels[0] == "0 s" and labels[-1] == "6 s"
        assert set(labels) <= {f"{k / 10:g} s" for k in idx}


def test_topview_every_and_single(mpc_run):
    fig = plots.topview_single(mpc_run, every_s=0.5)
    assert len(fig.axes) == 1
    assert len(by_gid(fig, "hv-snapshot")) == len(range(0, 62, 5))
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ConfigError, match="every"):
            plots.topview_single(mpc_run, every_s=bad)


def label_boxes(fig):
    """Per axes: the time labels as ``(who, text, bbox in data coordinates)``."""
    renderer = fig.canvas.get_renderer()
    found = []
    for ax in fig.axes:
        to_data = ax.transData.inverted()
        found.append([(t.get_gid()[:2], t.get_text(),
                       t.get_window_extent(renderer).transformed(to_data))
                      for t in ax.texts if str(t.get_gid()).endswith("-time-label")])
    return found


def assert_labels_clear(fig):
    """No time label on a vehicle footprint (of either vehicle) or out of its axes."""
    for ax, labels in zip(fig.axes, label_boxes(fig)):
        assert len(labels) >= 4  # at least the first and last of each vehicle
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        snaps = {who: [Bbox.from_extents(*p.get_xy().min(axis=0), *p.get_xy().max(axis=0))
                       for p in by_gid(ax, f"{who}-snapshot")]
                 for who in ("hv", "av")}
        for who, text, box in labels:
            other = "av" if who == "hv" else "hv"
            assert not any(box.overlaps(s) for s in snaps[other]), (who, text, "other vehicle")
            assert not any(box.overlaps(s) for s in snaps[who]), (who, text, "own vehicle")
            assert x0 <= box.x0 and box.x1 <= x1 and y0 <= box.y0 and box.y1 <= y1, (who, text)
        for i, (_, text_a, a) in enumerate(labels):  # and no two labels on each other
            for _, text_b, b in labels[i + 1:]:
                assert not a.overlaps(b), (text_a, text_b)


def test_seed_996_time_labels_clear_every_vehicle(topview):
    assert_labels_clear(topview)


@pytest.mark.parametrize("seed", [3, 17])
def test_time_labels_clear_every_vehicle_for_other_runs(seed):
    runs = [simulate(Config().with_overrides({"av.kind": av}), seed)
            for av in ("lfg", "persuasive")]
    assert_labels_clear(plots.topview_figure(*runs))
    assert_labels_clear(plots.topview_single(runs[1], every_s=0.5))


def test_time_labels_sit_on_the_far_side_of_their_road(topview, lfg_run):
    half = lfg_run.config.vehicle.lane_width_m / 2
    (lfg_labels, mpc_labels) = label_boxes(topview)
    # 2-LFG: the AV stops short of the HV's road, so all HV labels are right of it.
    assert all(box.x0 > half for who, _, box in lfg_labels if who == "hv")
    # MPC AV: the HV stays below the AV's road, so all AV labels are above it.
    assert all(box.y0 > half for who, _, box in mpc_labels if who == "av")
    for labels in (lfg_labels, mpc_labels):  # every label beside its own road
        for who, text, box in labels:
            across = (box.y0, box.y1) if who == "av" else (box.x0, box.x1)
            assert across[0] > half or across[1] < -half, (who, text)


class _Pedal:
    """A person at the HV's pedals, scripted: full throttle for 2 s, braking for 1.5 s, then
    throttle again (what a trial of 'persuasive drive' records, without a browser)."""

    log_columns = ()
    draws_per_step = 0

    def reset(self, context, rng=None):
        pass

    def act(self, observation):
        t = observation.t_s
        return 1.0 if t < 2.0 else (-2.0 if t < 3.5 else 1.0)


def person_trial(seed, overrides=None):
    """A run with a person as the HV (``hv.kind = "person"``), as a drive trial records it."""
    from persuasive.world import PythonWorld

    config = Config(mode="corrected").with_overrides({"hv.kind": "person", **(overrides or {})})
    world = PythonWorld(config, seed, hv=_Pedal())
    while not world.done:
        world.step()
    return world.record()


#: Lines of the top view that no time label may touch.
DRAWN_LINES = ("av-path", "hv-path", "av-crossing-line", "hv-crossing-line", "av-yield-line",
               "hv-yield-line", "conflict-point")


def assert_labels_readable(fig):
    """Every time label, as the renderer lays it out: no two overlap, none touches a drawn line
    (the paths, the crossing and yield lines, the conflict point) or a footprint, and each
    vehicle's labels sit on one side of its path, in time order along it."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        texts = [t for t in ax.texts if str(t.get_gid()).endswith("-time-label")]
        boxes = [t.get_window_extent(renderer) for t in texts]
        for i, (a, ta) in enumerate(zip(boxes, texts)):
            for b, tb in zip(boxes[i + 1:], texts[i + 1:]):
                assert not a.overlaps(b), (ta.get_gid(), ta.get_text(), tb.get_gid(),
                                           tb.get_text())
        for line in ax.get_lines():
            if line.get_gid() not in DRAWN_LINES:
                continue
            path = line.get_path().transformed(line.get_transform())
            marker = line.get_marker() not in (None, "None", "")
            for box, text in zip(boxes, texts):
                grown = box.expanded(1.0, 1.0).padded(line.get_linewidth() / 2 * fig.dpi / 72)
                hit = grown.count_contains(path.vertices) if marker else \
                    path.intersects_bbox(grown, filled=False)
                assert not hit, (text.get_gid(), text.get_text(), line.get_gid())
        for patch in by_gid(ax, "hv-snapshot") + by_gid(ax, "av-snapshot"):
            outline = patch.get_path().transformed(patch.get_transform())
            for box, text in zip(boxes, texts):
                assert not outline.intersects_bbox(box, filled=True), (text.get_gid(),
                                                                      text.get_text())
        for who in ("hv", "av"):
            mine = [(float(t.get_text()[:-2]), t.get_position()) for t in texts
                    if t.get_gid() == f"{who}-time-label"]
            (path,) = [ln for ln in ax.get_lines() if ln.get_gid() == f"{who}-path"]
            xy = np.asarray(path.get_xydata(), float)
            sides, along = [], []
            for _, (x, y) in sorted(mine):
                j = int(np.argmin(np.hypot(xy[:, 0] - x, xy[:, 1] - y)))
                a, b = xy[max(j - 1, 0)], xy[min(j + 1, len(xy) - 1)]
                if np.allclose(a, b):  # a vehicle that did not move
                    continue
                tangent = b - a
                sides.append(np.sign(tangent[0] * (y - xy[j, 1]) - tangent[1] * (x - xy[j, 0])))
                along.append(j)
            assert len(set(sides)) <= 1, (who, "labels on both sides of the road")
            assert along == sorted(along), (who, "labels out of time order")


def _pair(config, seed=996):
    return [simulate(config.with_overrides({"av.kind": av}), seed) for av in ("lfg",
                                                                             "persuasive")]


@pytest.mark.parametrize("overrides", [
    {"scenario.kind": "crossing", "scenario.angle_deg": 60.0},
    {"scenario.kind": "merge"},
    {"scenario.kind": "left-turn"},
    {},
], ids=["crossing-60", "merge", "left-turn", "intersection"])
def test_time_labels_touch_nothing_and_read_in_order(overrides):
    runs = _pair(Config().with_overrides(overrides))
    assert_labels_readable(plots.topview_figure(*runs))
    assert_labels_readable(plots.topview_single(runs[1]))


@pytest.mark.parametrize("seed, overrides", [
    (3, {}), (5, {"scenario.kind": "crossing", "scenario.angle_deg": 60.0}),
    (7, {"scenario.kind": "merge", "simulation.n_steps": 80}),
], ids=["intersection", "crossing-60", "merge-8-s"])
def test_time_labels_of_a_drive_trial_touch_nothing(seed, overrides):
    trial = person_trial(seed, overrides)
    assert trial.config.hv.kind == "person"
    assert_labels_readable(plots.topview_single(trial))
    assert_labels_readable(plots.topview_single(trial, every_s=0.5))


def test_legends_name_who_drives_the_hv():
    from persuasive.plots.animation import _AnimationScene

    def legend_texts(fig):
        return {t.get_text() for lg in fig.findobj(Legend) for t in lg.get_texts()}

    idm = simulate(Config().with_overrides({"hv.kind": "idm", "simulation.n_steps": 12}), 3)
    trial = person_trial(3, {"simulation.n_steps": 12})
    for run, name in ((idm, "HV (human-driven, IDM)"), (trial, "HV (driven by a person)")):
        for fig in (plots.profile_single(run), plots.topview_single(run),
                    _AnimationScene(run, 8.0, 4.0, 120.0).fig):
            texts = legend_texts(fig)
            assert name in texts and not any("LFG" in t for t in texts), texts
    lfg = simulate(Config().with_overrides({"simulation.n_steps": 12}), 3)
    assert "HV (human-driven, LFG / IDM)" in legend_texts(plots.topview_figure(lfg, idm))


def test_a_profile_says_why_its_role_row_is_empty():
    trial = person_trial(3, {"simulation.n_steps": 20})
    ax_role = plots.profile_single(trial).axes[0]
    assert by_gid(ax_role, "hv-role") == [] and by_gid(ax_role, "av-role") == []
    assert one(ax_role, "hv-no-role").get_text() == "HV (a person): no role"
    assert one(ax_role, "av-no-role").get_text() == "AV (branch MPC): no role"
    idm = simulate(Config().with_overrides({"hv.kind": "idm", "av.kind": "lfg",
                                            "simulation.n_steps": 20}), 3)
    ax_role = plots.profile_single(idm).axes[0]
    assert one(ax_role, "hv-no-role").get_text() == "HV (IDM): no role"
    assert by_gid(ax_role, "av-no-role") == [] and by_gid(ax_role, "av-role")


def test_compare_figure_says_0_or_n_a_for_delays_it_cannot_draw():
    import pandas as pd

    nan = float("nan")
    rows = [  # (av, hv, AV delays, HV delays) of three seeds
        ("persuasive", "lfg", [0.1, 0.3, 0.2], [0.0, 0.0, 0.0]),
        ("persuasive", "idm", [0.0, 0.0, 0.0], [nan, nan, nan]),
        ("yield", "lfg", [nan, nan, nan], [0.4, 0.5, 0.45]),
        ("yield", "idm", [nan, nan, nan], [0.0, 0.0, 0.0]),
    ]
    runs = pd.DataFrame([{"av.kind": av, "hv.kind": hv, "av_delay_s": a, "hv_delay_s": h,
                          "seed": k + 1}
                         for av, hv, ad, hd in rows for k, (a, h) in enumerate(zip(ad, hd))])
    summary = {"av_kinds": ["persuasive", "yield"], "hv_kinds": ["lfg", "idm"],
               "scenario": "intersection", "mode": "corrected", "seeds": 3,
               "rows": [{"av": av, "hv": hv, "av_first_pct": 50.0, "av_first_pct_ci": [0, 100],
                         "collisions": 0} for av, hv, _, _ in rows]}
    fig = plots.compare_figure(summary, runs)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    ax = fig.axes[-1] if len(fig.axes) == 2 else fig.axes[1]
    notes = {t.get_gid(): t for t in fig.findobj() if str(t.get_gid()).startswith("delay-note")}
    assert {g: t.get_text() for g, t in notes.items()} == {
        "delay-note-persuasive-lfg": "HV 0", "delay-note-persuasive-idm": "AV 0, HV n/a",
        "delay-note-yield-lfg": "AV n/a", "delay-note-yield-idm": "AV n/a, HV 0"}
    boxes = [b for b in fig.findobj() if b.get_gid() == "delay-box"]
    for note in notes.values():  # never over a box
        extent = note.get_window_extent(renderer)
        assert not any(b.get_window_extent(renderer).overlaps(extent) for b in boxes)
        assert ax.get_window_extent(renderer).contains(extent.x1 - 1, extent.y0 + 1)


# -- table figure -------------------------------------------------------------------------------


def test_table_bars_and_published_markers(summary):
    fig = plots.table_figure(summary)
    ax = fig.axes[0]
    rows = summary["rows"]
    assert len(rows) == len(PUBLISHED["table2"]) == 14
    for who in ("av", "hv"):
        bars = by_gid(ax, f"{who}-first")
        assert len(bars) == 14
        order = np.argsort([bar.get_y() for bar in bars])  # paper order, top first
        widths = [bars[i].get_width() for i in order]
        np.testing.assert_array_equal(widths, [r[f"{who}_first_pct"] for r in rows])
        marks = one(ax, f"{who}-published")
        np.testing.assert_array_equal(marks.get_xdata(),
                                      [r[f"published_{who}_first_pct"] for r in rows])
        np.testing.assert_array_equal(marks.get_xdata(),
                                      [getattr(row, f"published_{who}_first_pct")
                                       for row in PUBLISHED["table2"]])
        # each marker sits on its own row's bar
        np.testing.assert_allclose(marks.get_ydata(),
                                   [bars[i].get_y() + bars[i].get_height() / 2 for i in order])
    labels = [t.get_text() for t in ax.get_yticklabels()]
    assert labels == [plots.table_row_label(r) for r in rows]
    assert labels[8].startswith("L, ") and "0.98" in labels[8] and "hat" in labels[8]
    assert "Table 2" in ax.get_title() and "seeds 1..2" in ax.get_title()


def test_table_rejects_a_summary_without_rows(summary):
    with pytest.raises(ConfigError):
        plots.table_figure({"table": "table2", "mode": "paper", "seeds": 1, "rows": []})
    with pytest.raises(ConfigError, match="rows"):
        plots.table_figure({"table": "table2"})


# -- animation ----------------------------------------------------------------------------------


def test_animation_frames_follow_the_run(short_run):
    frames = list(plots.animation_frames(short_run))
    assert len(frames) == len(short_run.log["step"]) == 25
    assert {f.shape for f in frames} == {(480, 960, 3)} and frames[0].dtype == np.uint8
    red, blue = colour_pixels(frames[0])
    assert red > 100 and blue > 100

    def centroid(frame, colour):  # of a vehicle's pixels in the top view (left half)
        rgb = frame[:, :480].astype(int)
        r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
        mask = ((r > 180) & (g < 90) & (b < 90)) if colour == "red" else \
            ((b > 150) & (r < 80) & (g > 80) & (g < 160))
        ys, xs = np.nonzero(mask)
        return xs.mean(), ys.mean()

    # The AV drives right (+x), the HV up (+y: image rows decrease), as in the states.
    av_dx = centroid(frames[-1], "red")[0] - centroid(frames[0], "red")[0]
    hv_dy = centroid(frames[-1], "blue")[1] - centroid(frames[0], "blue")[1]
    assert av_dx > 10 and hv_dy < -10
    assert short_run.states[24, 0] > short_run.states[0, 0]


def test_gif_has_one_frame_per_step(short_run, tmp_path):
    path = plots.animate(short_run, tmp_path / "run.gif", fps=5)
    frames = iio3.imread(path, index=None)
    assert frames.shape[0] == 25
    assert iio3.immeta(path)["duration"] == 200  # ms, from fps = 5
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.gif"]


def test_mp4_has_one_frame_per_step(short_run, tmp_path):
    path = plots.animate(short_run, tmp_path / "run.mp4")
    reader = iio2.get_reader(path, format="FFMPEG")
    try:
        assert sum(1 for _ in reader) == 25
        assert reader.get_meta_data()["fps"] == 10
    finally:
        reader.close()


def test_animation_has_a_key_to_the_top_view(short_run):
    from persuasive.plots.animation import _AnimationScene

    scene = _AnimationScene(short_run, 8.0, 4.0, 120.0)
    entries = {}
    for legend in scene.fig.findobj(Legend):
        for handle, text in zip(legend.legend_handles, legend.get_texts()):
            entries[text.get_text()] = handle
    vehicles = {"HV (human-driven, LFG)": plots.HV_COLOR, "AV (autonomous)": plots.AV_COLOR}
    for label, colour in vehicles.items():
        assert np.allclose(entries[label].get_facecolor(), to_rgba(colour)), label
    assert entries["crossing line"].get_linestyle() == "-"
    assert entries["safe distance 7.5 m"].get_linestyle() == ":"
    # the key and the status text do not overlap
    renderer = scene.canvas.get_renderer()
    scene.render(0)
    key = next(lg for lg in scene.fig.findobj(Legend) if "crossing line" in
               [t.get_text() for t in lg.get_texts()])
    assert not key.get_window_extent(renderer).overlaps(scene.text.get_window_extent(renderer))


def test_first_animation_frame_shows_both_beliefs(short_run):
    from persuasive.plots.animation import _AnimationScene

    scene = _AnimationScene(short_run, 8.0, 4.0, 120.0)
    frame = scene.render(0)
    np.testing.assert_array_equal(frame, next(plots.animation_frames(short_run)))
    ax = scene.ax_belief
    for who in ("hv", "av"):
        drawn = np.concatenate([np.c_[line.get_xdata(), line.get_ydata()]
                                for line in ax.get_lines()
                                if str(line.get_gid()).startswith(f"{who}-belief")])
        initial = short_run.log[plots.belief_column(short_run, who)][0]
        assert [0.0, initial] in drawn.tolist(), who
    # and it is in the pixels: both colours inside the belief axes (image rows run down)
    box = ax.get_window_extent()
    height = frame.shape[0]
    inside = frame[int(height - box.y1) - 5:int(height - box.y0) + 5,
                   int(box.x0) - 5:int(box.x1) + 5]
    red, blue = colour_pixels(inside)
    assert red > 5 and blue > 5


@pytest.mark.parametrize("ext", [".mp4", ".gif"])
def test_failed_animation_write_leaves_the_target_and_no_temporary(short_run, tmp_path,
                                                                   monkeypatch, ext):
    from persuasive.plots import animation

    def mismatched_frames(run, dpi=120.0):  # the encoder refuses the second frame
        yield np.zeros((480, 960, 3), np.uint8)
        yield np.zeros((240, 960, 3), np.uint8)

    monkeypatch.setattr(animation, "animation_frames", mismatched_frames)
    target = tmp_path / f"run{ext}"
    target.write_bytes(b"old")
    with pytest.raises(OutputError) as info:
        plots.animate(short_run, target)
    message = str(info.value)
    assert message.startswith(f"cannot write {str(target)!r}: ") and "\n" not in message
    del info
    gc.collect()  # a writer left open would now finish its file
    assert target.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]


def test_animation_rejects_bad_extension_and_fps(short_run, tmp_path):
    with pytest.raises(ConfigError, match="unsupported extension '.avi'"):
        plots.animate(short_run, tmp_path / "run.avi")
    with pytest.raises(ConfigError, match="fps"):
        plots.animate(short_run, tmp_path / "run.gif", fps=0)
    assert list(tmp_path.iterdir()) == []


# -- command line -------------------------------------------------------------------------------


def test_plot_commands_default_to_seed_996_and_keep_simulate_at_1():
    plot = cli.commands["plot"]
    for command in (plot.commands["profile"], plot.commands["topview"], cli.commands["animate"]):
        assert {p.name: p.default for p in command.params}["seed"] == 996
    assert {p.name: p.default for p in cli.commands["simulate"].params}["seed"] == 1


def test_cli_profile_and_topview(tmp_path, capsys):
    out = tmp_path / "profile.png"
    assert main(["plot", "profile", "--set", "simulation.n_steps=30", "--out", str(out)]) == 0
    assert out.read_bytes()[:4] == b"\x89PNG"
    assert f"wrote {out}" in capsys.readouterr().out
    svg = tmp_path / "single.svg"
    assert main(["plot", "profile", "--single", "--av", "lfg", "--seed", "3",
                 "--out", str(svg)]) == 0
    assert b"<svg" in svg.read_bytes()[:400]
    assert b'id="av-role"' in svg.read_bytes()  # --single --av lfg: one LFG AV's role line
    pdf = tmp_path / "top.pdf"
    assert main(["plot", "topview", "--every", "0.5", "--hv-role", "follower",
                 "--out", str(pdf)]) == 0
    assert pdf.read_bytes()[:4] == b"%PDF"


def test_cli_table_and_animate(results_dir, tmp_path):
    out = tmp_path / "table.png"
    assert main(["plot", "table", "--from", str(results_dir), "--out", str(out)]) == 0
    red, blue = colour_pixels(mpimg.imread(out))
    assert red > 500 and blue > 500
    gif = tmp_path / "run.gif"
    assert main(["animate", "--set", "simulation.n_steps=12", "--fps", "5",
                 "--out", str(gif)]) == 0
    assert iio3.imread(gif, index=None).shape[0] == 12


@pytest.fixture(scope="module")
def saved_run(tmp_path_factory, short_run):
    path = tmp_path_factory.mktemp("saved") / "run.parquet"
    short_run.save(path)
    return path


@pytest.mark.parametrize("command, out", [(["plot", "profile"], "f.png"),
                                          (["plot", "topview"], "f.png"),
                                          (["animate"], "f.gif")])
@pytest.mark.parametrize("options, names", [
    (["--seed", "5"], "--seed"),
    (["--av", "lfg", "--hv", "idm"], "--av, --hv"),
    (["--hv-role", "follower", "--pa", "0.5", "--pa-hat", "0.9"], "--hv-role, --pa, --pa-hat"),
    (["--scenario", "merge", "--mode", "corrected"], "--scenario, --mode"),
    (["--config", "{config}", "--set", "mpc.epsilon=0.05"], "--config, --set"),
    (["--seed", "996"], "--seed"),  # even the default, given explicitly
], ids=["seed", "kinds", "roles", "scenario-mode", "config-set", "default-seed"])
def test_options_that_from_overrides_are_refused(tmp_path, capsys, saved_run, command, out,
                                                  options, names):
    (tmp_path / "c.toml").write_text('mode = "paper"\n')
    argv = [*command, "--from", str(saved_run), "--out", str(tmp_path / out),
            *[o.format(config=tmp_path / "c.toml") for o in options]]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err == f"error: {names} cannot be used with --from: the saved run has its own " \
                  "seed and configuration\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.toml"]


def test_single_is_refused_with_from_and_from_alone_plots(tmp_path, capsys, saved_run,
                                                          short_run):
    assert main(["plot", "profile", "--single", "--from", str(saved_run), "--out",
                 str(tmp_path / "f.png")]) == 2
    assert "--single cannot be used with --from" in capsys.readouterr().err
    assert main(["plot", "profile", "--from", str(saved_run), "--out",
                 str(tmp_path / "f.png")]) == 0
    assert (tmp_path / "f.png").read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize("args, message", [
    (["plot", "profile", "--out", "{out}.jpg"], "unsupported extension"),
    (["plot", "profile", "--pa", "2", "--out", "{out}.png"], "roles.p_a"),
    (["plot", "profile", "--av", "lfg", "--out", "{out}.png"], "--single"),
    (["plot", "topview", "--every", "0", "--out", "{out}.png"], "--every"),
    (["plot", "table", "--from", "{missing}", "--out", "{out}.png"], "summary.json"),
    (["animate", "--out", "{out}.avi"], "unsupported extension"),
    (["animate", "--fps", "0", "--out", "{out}.gif"], "--fps"),
    (["plot", "profile"], "--out"),
])
def test_cli_bad_input_is_one_line_and_exit_2(tmp_path, capsys, args, message):
    old = {ext: tmp_path / f"fig{ext}" for ext in (".png", ".gif")}
    for path in old.values():
        path.write_bytes(b"old")
    argv = [a.format(out=tmp_path / "fig", missing=tmp_path / "no-results") for a in args]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and message in err
    assert "Traceback" not in err
    for path in old.values():  # nothing written, nothing lost
        assert path.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig.gif", "fig.png"]
