"""The command line reads its kinds from the registries, and its table of who reads which run
option is true.

Every choice and help text listing AV planners, human kinds, scenarios, shields or roles is
built from :mod:`persuasive.config` and :mod:`persuasive.policies.kinds` (and the gymnasium
ids from :data:`persuasive.scenarios.SCENARIOS`): a new kind appears everywhere with no CLI
edit. The first tests compare with the registries; the subprocess test adds a kind of each
registry before the CLI is imported, which a hand-written list fails. The last tests check
:data:`persuasive.cli._common.KIND_OPTIONS` against what the policies actually read.
"""

from __future__ import annotations

import json
import subprocess
import sys

import click
import numpy as np
import pytest

from persuasive.cli import cli
from persuasive.cli._common import KIND_OPTIONS, SHIELD_HELP, kinds_text
from persuasive.config import (AV_KIND_ALIASES, AV_KINDS, MANY_SCENARIO_KINDS, ROLES,
                               SCENARIO_KINDS, SHIELD_KINDS, SIMULATED_HV_KINDS, Config)
from persuasive.policies import kinds as kd
from persuasive.policies import policy_params
from persuasive.scenarios import SCENARIOS
from persuasive.simulation import simulate

#: The commands of this package's CLI whose options list kinds (sumo's scenarios are the two
#: its network builder makes, and fit's models its own: both are left to their modules).
RUN_COMMANDS = (("simulate",), ("plot", "profile"), ("plot", "topview"), ("animate",))


def command(*path: str) -> click.Command:
    group = cli
    for name in path:
        group = group.commands[name]
    return group


def option(cmd: click.Command, name: str) -> click.Parameter:
    (param,) = [p for p in cmd.params if p.name == name]
    return param


def choices(cmd: click.Command, name: str) -> list[str]:
    return list(option(cmd, name).type.choices)


def help_of(cmd: click.Command, name: str) -> str:
    return " ".join(option(cmd, name).help.split())


@pytest.mark.parametrize("path", RUN_COMMANDS, ids=" ".join)
def test_run_options_list_exactly_the_registries(path):
    cmd = command(*path)
    assert choices(cmd, "av") == [*AV_KINDS, *AV_KIND_ALIASES]
    assert choices(cmd, "hv") == list(SIMULATED_HV_KINDS)
    assert choices(cmd, "scenario") == [*SCENARIO_KINDS, *MANY_SCENARIO_KINDS]
    assert choices(cmd, "shield") == list(SHIELD_KINDS)
    assert choices(cmd, "hv_role") == list(ROLES)
    assert f": {kinds_text(AV_KINDS, {'lfg': 'the 2-LFG case'})} (docs" in help_of(cmd, "av")
    assert help_of(cmd, "hv").endswith(f": {', '.join(SIMULATED_HV_KINDS)}.")
    assert help_of(cmd, "scenario").endswith(f": {', '.join(SCENARIO_KINDS)}, junction (N "
                                             "vehicles, --vehicles).")
    assert f": {', '.join(SHIELD_KINDS)} [" in help_of(cmd, "shield")


def test_other_commands_list_exactly_the_registries():
    from persuasive.studies.compare import DEFAULT_HV_KINDS

    compare = command("compare")
    assert choices(compare, "scenario") == [*SCENARIO_KINDS, *MANY_SCENARIO_KINDS]
    assert choices(compare, "hv_role") == list(ROLES)
    assert f"[all: {','.join(AV_KINDS)}]" in help_of(compare, "av_kinds")
    assert help_of(compare, "hv_kinds").endswith(f"[all but replay: "
                                                 f"{','.join(DEFAULT_HV_KINDS)}].")
    assert f"comma-separated, of {', '.join(SHIELD_KINDS)} (docs" in help_of(compare, "shields")
    assert choices(command("reproduce"), "scenario") == list(SCENARIO_KINDS)
    assert help_of(command("reproduce"), "scenario").endswith(f": {', '.join(SCENARIO_KINDS)}.")
    highway = command("highway")
    assert choices(highway, "planner") == [*AV_KINDS, *AV_KIND_ALIASES]
    assert choices(highway, "shield") == list(SHIELD_KINDS)
    assert f": {', '.join(SHIELD_KINDS)} [" in help_of(highway, "shield")
    assert choices(command("bench"), "av") == list(AV_KINDS)
    assert choices(command("bench"), "scenario") == [*SCENARIO_KINDS, *MANY_SCENARIO_KINDS]
    for name in ("sweep", "drive"):
        assert choices(command(name), "shield") == list(SHIELD_KINDS)
        assert help_of(command(name), "shield") == SHIELD_HELP


def test_gym_ids_follow_the_scenario_registry():
    from persuasive.envs import ENV_IDS, env_id

    assert list(ENV_IDS) == list(SCENARIOS) == list(SCENARIO_KINDS)
    assert ENV_IDS["left-turn"] == env_id("left-turn") == "persuasive/LeftTurn-v0"
    assert ENV_IDS["intersection"] == "persuasive/Intersection-v0"


#: Adds a kind to each registry, then imports the CLI and prints what its options offer.
_PATCHED = r"""
import json, sys
import click
import persuasive.config as config
import persuasive.scenarios as scenarios

for module in ("persuasive.cli", "persuasive.studies.compare", "persuasive.envs"):
    assert module not in sys.modules, module  # built after the registries are patched
config.AV_KINDS = (*config.AV_KINDS, "newplanner")
config.SIMULATED_HV_KINDS = (*config.SIMULATED_HV_KINDS, "newhuman")
config.SCENARIO_KINDS = (*config.SCENARIO_KINDS, "roundabout")
config.SHIELD_KINDS = (*config.SHIELD_KINDS, "newshield")
scenarios.SCENARIOS["roundabout"] = None

from persuasive.cli import cli
from persuasive.envs import ENV_IDS

out = {"env_ids": ENV_IDS}
def walk(group, prefix=()):
    for name, cmd in group.commands.items():
        if isinstance(cmd, click.Group):
            walk(cmd, prefix + (name,))
        else:
            out[" ".join(prefix + (name,))] = {
                p.name: {"choices": list(getattr(p.type, "choices", []) or []),
                         "help": " ".join((getattr(p, "help", None) or "").split())}
                for p in cmd.params}
walk(cli)
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def patched():
    """What the CLI offers when each registry holds one kind more."""
    done = subprocess.run([sys.executable, "-c", _PATCHED], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


@pytest.mark.parametrize("name, param, new", [
    (name, param, new) for name in ("simulate", "plot profile", "plot topview", "animate")
    for param, new in (("av", "newplanner"), ("hv", "newhuman"), ("scenario", "roundabout"),
                       ("shield", "newshield"))
] + [
    ("compare", "scenario", "roundabout"), ("reproduce", "scenario", "roundabout"),
    ("highway", "planner", "newplanner"), ("highway", "shield", "newshield"),
    ("bench", "av", "newplanner"), ("bench", "scenario", "roundabout"),
    ("sweep", "shield", "newshield"), ("drive", "shield", "newshield"),
])
def test_a_new_kind_is_offered_with_no_cli_edit(patched, name, param, new):
    entry = patched[name][param]
    assert new in entry["choices"]
    if name != "bench":  # bench's help texts name no kinds (its choices do)
        assert new in entry["help"]


def test_a_new_kind_reaches_the_comma_separated_lists(patched):
    compare = patched["compare"]
    assert f"{','.join(AV_KINDS)},newplanner]" in compare["av_kinds"]["help"]
    assert ",random,newhuman]" in compare["hv_kinds"]["help"]
    assert "newshield" in compare["shields"]["help"]
    assert patched["env_ids"]["roundabout"] == "persuasive/Roundabout-v0"


# -- KIND_OPTIONS is what the policies read -----------------------------------------------------


def _params(config: Config, side: int) -> np.ndarray:
    return policy_params(config, side)


@pytest.mark.parametrize("name, field, values", [
    ("pa", "roles.p_a", (0.3, 0.6)), ("hv_role", "hv.role", ROLES)])
def test_the_humans_that_read_an_option_are_those_listed(name, field, values):
    readers = []
    for kind in SIMULATED_HV_KINDS:
        if kind == "replay":  # needs a recording; it replays accelerations, nothing else
            continue
        a, b = (Config().with_overrides({"hv.kind": kind, field: v}) for v in values)
        if not np.array_equal(_params(a, kd.HV), _params(b, kd.HV)):
            readers.append(kind)
    assert tuple(readers) == KIND_OPTIONS[name].hv_kinds


def test_the_avs_that_read_an_option_are_those_listed():
    # mpc.p_a_hat fixed, so that roles.p_a is not the persuasive AV's estimate
    base = Config().with_overrides({"mpc.p_a_hat": 0.5, "hv.kind": "idm"})
    readers = []
    for kind in AV_KINDS:
        a, b = (base.with_overrides({"av.kind": kind, "roles.p_a": v}) for v in (0.3, 0.6))
        if not np.array_equal(_params(a, kd.AV), _params(b, kd.AV)):
            readers.append(kind)
    assert tuple(readers) == KIND_OPTIONS["pa"].av_kinds == ("lfg",)


@pytest.mark.parametrize("kind", AV_KINDS)
def test_only_the_persuasive_av_acts_on_its_estimate_and_no_av_but_lfg_on_the_human_role(kind):
    """Whole runs, not parameter vectors: the passive planner carries p_a_hat but its role
    transition is the identity; outside paper mode's quirk Q3 the persuasive planners never
    read the human's initial role."""
    base = Config(mode="corrected").with_overrides({"av.kind": kind, "hv.kind": "lfg",
                                                     "roles.p_a": 0.5})
    differs = False
    for seed in (1, 2, 3, 996):
        low, high = (simulate(base.with_overrides({"mpc.p_a_hat": v}), seed)
                     for v in (0.0, 1.0))
        differs |= not np.array_equal(low.states, high.states)
    assert differs == (kind in KIND_OPTIONS["pa_hat"].av_kinds)
    base = base.with_overrides({"hv.kind": "idm"})  # a human without a role
    differs = False
    for seed in (1, 2, 3, 996):
        lead, follow = (simulate(base.with_overrides({"hv.role": r}), seed) for r in ROLES)
        differs |= not np.array_equal(lead.states, follow.states)
    assert differs == (kind in KIND_OPTIONS["hv_role"].av_kinds)
