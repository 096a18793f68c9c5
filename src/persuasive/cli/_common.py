"""What every command shares: building the configuration, the run options, output checks
and the one-writer lock of an output (:func:`lock_output`).

Precedence, the same for every command: an explicit option (``--mode``, ``--av``, ``--pa``,
...) beats ``--set section.field=value``, which beats ``--config FILE.toml``, which beats the
defaults (the paper's values).

Every list of kinds a command offers (its ``click.Choice`` and its help) is read from the
registries of :mod:`persuasive.config` (``AV_KINDS``, ``SIMULATED_HV_KINDS``,
``SCENARIO_KINDS``, ``SHIELD_KINDS``, ``ROLES``) and :mod:`persuasive.policies.kinds`, in their
order, so that a new planner, human kind or scenario needs no edit here. Every integer option
takes :class:`Count`, whose message names the allowed range whatever the mistake (``1e9``,
``0``, ``x``).

Options only some kinds read (``--pa``, ``--pa-hat``, ``--hv-role``; see
:data:`KIND_OPTIONS`) are refused, with exit status 2, when given explicitly for a run whose
kinds all ignore them (:func:`check_kind_options`): the user asked for something that would
silently do nothing. The same fields coming from ``--config``, ``--set`` or the defaults are
not refused (a configuration file is shared between kinds; ``--set`` sets a field as given):
``simulate`` says in its summary which of them the run ignores (:func:`ignored_fields`).
"""

from __future__ import annotations

import os
import sys
import tomllib
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping, Sequence

import click

from ..config import (AV_KIND_ALIASES, AV_KINDS, MANY_SCENARIO_KINDS, MODES, ROLES,
                      SCENARIO_KINDS, SHIELD_KINDS, SIMULATED_HV_KINDS, Config, ConfigError,
                      read_toml)
from ..policies.kinds import AV, HV, KINDS

#: Seed of the run the paper shows in its Figs. 2 and 3 (the default of the figure commands).
PAPER_SEED = 996
#: Largest run seed (``persuasive.simulation.check_seed``; numpy's SeedSequence takes more,
#: the legacy streams do not).
SEED_MAX = 2**32 - 1
#: The defaults the help texts name (the paper's values).
_DEFAULTS = Config()


def kinds_text(kinds: Iterable[str], notes: Mapping[str, str] | None = None,
               sep: str = ", ") -> str:
    """``kinds`` in their registry's order, for a help text or a message; ``notes`` adds a
    word in brackets after a kind (a kind it does not name is listed plain)."""
    notes = notes or {}
    return sep.join(f"{k} ({notes[k]})" if k in notes else k for k in kinds)


def kinds_with(side: int, has_role: bool | None = None) -> tuple[str, ...]:
    """The simulated kinds of one side (``policies.kinds.AV`` / ``HV``), in the order of the
    configuration's registry (``AV_KINDS`` / ``SIMULATED_HV_KINDS``); ``has_role``: only those
    that hold (True) or do not hold (False) a leader/follower role."""
    names = AV_KINDS if side == AV else SIMULATED_HV_KINDS
    return tuple(k for k in names if k in KINDS and side in KINDS[k].sides
                 and (has_role is None or KINDS[k].has_role == has_role))


class _RangeError(click.BadParameter):
    """A bad integer option: ``--name = value is out of range; allowed: ...`` (the form of
    every configuration error), without click's "Invalid value for" preamble."""

    def format_message(self) -> str:
        return self.message


class Count(click.IntRange):
    """An integer option in ``[min, max]`` (``max=None``: unbounded) whose every error, a
    value out of range or no integer at all (``1e9``, ``x``), names the allowed range:
    ``--episodes = 1e9 is out of range; allowed: integer in [1, 10000]``. ``why`` is added in
    brackets (e.g. what the bound protects)."""

    def __init__(self, min: int, max: int | None = None, why: str | None = None):
        super().__init__(min=min, max=max)
        self.why = why

    def allowed(self) -> str:
        """The allowed range, as the messages write it."""
        text = (f"integer in [{self.min}, {self.max}]" if self.max is not None
                else f"integer >= {self.min}")
        return f"{text} ({self.why})" if self.why else text

    def convert(self, value, param, ctx):
        try:
            return super().convert(value, param, ctx)
        except click.BadParameter:
            name = param.opts[0] if param is not None and param.opts else "value"
            raise _RangeError(f"{name} = {value} is out of range; allowed: {self.allowed()}",
                              ctx=ctx, param=param) from None


def workers_type() -> Count:
    """``--workers``: 1 to 8 processes per core (:func:`check_workers`'s bound)."""
    cores = os.cpu_count() or 1
    return Count(1, 8 * cores, f"8 per core, {cores} cores")


def parse_set(values: tuple[str, ...]) -> dict[str, Any]:
    """``("section.field=value", ...)`` as a dict; values are read as TOML, else as text."""
    out: dict[str, Any] = {}
    for item in values:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--set {item!r} is not of the form section.field=value")
        try:
            value = tomllib.loads(f"v = {raw.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = raw.strip()  # a bare word, e.g. --set simulation.measurement_noise=uniform
        out[key.strip()] = value
    return out


def build_config(config_file: str | None, sets: tuple[str, ...],
                 explicit: dict[str, Any] | None = None) -> Config:
    """The configuration of a command: defaults < ``--config`` < ``--set`` < ``explicit``.

    ``explicit`` maps dotted fields to the values of explicit options; ``None`` values (an
    option not given) are ignored.
    """
    config = Config.from_toml(config_file) if config_file else Config()
    overrides = parse_set(sets)
    overrides.update({k: v for k, v in (explicit or {}).items() if v is not None})
    return config.with_overrides(overrides) if overrides else config


#: Explicit run options and the fields they set.
RUN_FIELDS = {"av": "av.kind", "hv": "hv.kind", "hv_role": "hv.role", "pa": "roles.p_a",
              "pa_hat": "mpc.p_a_hat", "scenario": "scenario.kind", "mode": "mode",
              "shield": "av.shield"}

#: Help of ``--shield`` (one setting).
SHIELD_HELP = (f"Safety shield around the AV planner (docs/method.md §12): "
               f"{kinds_text(SHIELD_KINDS)} [{Config(mode='paper').shield} in paper mode, "
               f"{Config(mode='corrected').shield} in corrected mode].")


def shield_option(func: Callable) -> Callable:
    """``--shield`` (one setting), setting ``av.shield``."""
    return click.option("--shield", type=click.Choice(list(SHIELD_KINDS)), default=None,
                        help=SHIELD_HELP)(func)


def scenario_option(help_text: str, many: bool = False) -> Callable:
    """``--scenario``: a kind of the scenario registry (``SCENARIO_KINDS``; with ``many``
    also the many-vehicle ``junction``), setting nothing itself (the command maps it to
    ``scenario.kind``); ``help_text`` is followed by the kinds."""
    kinds = (*SCENARIO_KINDS, *MANY_SCENARIO_KINDS) if many else SCENARIO_KINDS
    notes = {"junction": "N vehicles, --vehicles"} if many else None
    return click.option("--scenario", type=click.Choice(list(kinds)), default=None,
                        help=f"{help_text}: {kinds_text(kinds, notes)}.")


#: The junction's options (``--vehicles``, ``--variant``) and the fields they set.
JUNCTION_FIELDS = {"vehicles": "junction.n_vehicles", "variant": "junction.variant"}


def junction_options(func: Callable) -> Callable:
    """``--vehicles`` and ``--variant``: the junction of ``--scenario junction``."""
    from ..many.junction import VARIANTS

    for option in reversed([
        click.option("--vehicles", type=Count(1, 64), default=None,
                     help="Vehicles at the junction, the AV included (--scenario junction) "
                          "[4]."),
        click.option("--variant", type=click.Choice(list(VARIANTS)), default=None,
                     help="The junction's priority and movement mix (--scenario junction; "
                          "docs/guide/junction.md) [major]."),
    ]):
        func = option(func)
    return func


def run_explicit(options: dict[str, Any]) -> dict[str, Any]:
    """The dotted fields set by the run options of :func:`run_options` (given or not)."""
    return {field: options.get(name) for name, field in RUN_FIELDS.items()}


def junction_config(config: Config, options: Mapping[str, Any],
                    hv_kinds: str | None = None) -> Config:
    """``config`` with the junction's options applied: ``--vehicles`` and ``--variant`` are
    refused (exit status 2) unless ``scenario.kind = junction``; there, ``hv_kinds`` (the
    command's ``--hv``) sets the humans' kinds (``junction.hv_kinds``)."""
    given = {field: options[name] for name, field in JUNCTION_FIELDS.items()
             if options.get(name) is not None}
    if config.scenario.kind != "junction":
        if given:
            name = next(n for n, f in JUNCTION_FIELDS.items() if f in given)
            raise click.UsageError(f"--{name} is read only with --scenario junction (the "
                                   f"{config.scenario.kind} holds two vehicles)")
        return config
    if hv_kinds is not None:
        given["junction.hv_kinds"] = hv_kinds
    return config.with_overrides(given) if given else config


def kind_configs(config: Config) -> list[Config]:
    """The configurations whose kinds a run of ``config`` plays, for
    :func:`check_kind_options`: ``config`` itself, or at a junction one per human kind of
    ``junction.hv_kinds`` (with the paper's pair geometry,
    ``persuasive.many.junction.pair_config``)."""
    if config.scenario.kind != "junction":
        return [config]
    from ..many.junction import pair_config

    pair = pair_config(config)
    return [pair.with_overrides({"hv.kind": k}) for k, share in config.junction_spec.hv_kinds
            if share > 0.0]


def config_of(options: dict[str, Any]) -> Config:
    """The configuration the run options describe (see the precedence above); the
    junction's options last (:func:`junction_config`), and a junction in corrected mode
    unless a mode is given (:func:`mode_given`)."""
    explicit = run_explicit(options)
    # --hv is hv.kind for two vehicles, junction.hv_kinds at a junction (which the kind may
    # come from --config or --set): applied once the scenario is known
    hv = explicit.pop("hv.kind")
    config = build_config(options.get("config_file"), options.get("sets", ()), explicit)
    if hv is not None and config.scenario.kind != "junction":
        config = config.with_overrides({"hv.kind": hv})
    if config.scenario.kind == "junction" and not mode_given(options):
        config = config.with_overrides({"mode": "corrected"})
    return junction_config(config, options, hv)


def mode_given(options: Mapping[str, Any]) -> bool:
    """Whether ``--mode``, ``--set mode=...`` or the ``--config`` file sets the mode (else
    a junction runs in corrected mode: the paper published nothing for it)."""
    if options.get("mode") is not None or "mode" in parse_set(options.get("sets", ())):
        return True
    path = options.get("config_file")
    return bool(path) and "mode" in read_toml(path, "config file")


def config_options(func: Callable) -> Callable:
    """``--mode``, ``--config`` and ``--set``."""
    for option in reversed([
        click.option("--mode", type=click.Choice(list(MODES)), default=None,
                     help="paper (quirks Q1..Q7, docs/method.md §9) or corrected [paper; a junction: "
                          "corrected]."),
        click.option("--config", "config_file", type=click.Path(dir_okay=False), default=None,
                     help="TOML file of parameters."),
        click.option("--set", "sets", multiple=True, metavar="SECTION.FIELD=VALUE",
                     help="Override one parameter (repeatable), e.g. mpc.epsilon=0.05."),
    ]):
        func = option(func)
    return func


class _PaHat(click.ParamType):
    """A number or ``online`` (``mpc.p_a_hat``). Text that is neither is refused here with the
    range; a number out of ``[0, 1]`` (NaN included) by the configuration's check, which
    names the field and the same range."""

    name = "NUMBER|online"

    def convert(self, value, param, ctx):
        if isinstance(value, float) or value == "online":
            return value
        try:
            return float(value)
        except ValueError:
            name = param.opts[0] if param is not None and param.opts else "value"
            raise _RangeError(f"{name} = {value} is out of range; allowed: a number in "
                              "[0, 1] or online", ctx=ctx, param=param) from None


PA_HAT = _PaHat()

#: ``--interactions``: repeated interactions with one human per seed.
INTERACTIONS_HELP = ("Repeated interactions with one human per seed (same human, fresh "
                     "initial states; an online AV carries its posterior over p_a; "
                     "docs/method.md §13.9) [1].")


def run_options(seed_default: int = 1, seed_help: str = "Run seed.") -> Callable:
    """The options that define one closed-loop run (shared by simulate, plot and animate).

    ``--pa``, ``--pa-hat`` and ``--hv-role`` are read by some kinds only: a command calls
    :func:`check_kind_options` on the configurations it runs."""
    d = _DEFAULTS
    aliases = ", ".join(AV_KIND_ALIASES)
    options = [
        click.option("--av", type=click.Choice([*AV_KINDS, *AV_KIND_ALIASES]), default=None,
                     help=f"AV planner [{d.av.kind}; {aliases} is its old name]: "
                          f"{kinds_text(AV_KINDS, {'lfg': 'the 2-LFG case'})} "
                          "(docs/method.md §11)."),
        click.option("--hv", type=click.Choice(list(SIMULATED_HV_KINDS)), default=None,
                     help=f"Human model [{d.hv.kind}]: {kinds_text(SIMULATED_HV_KINDS)}."),
        click.option("--shield", type=click.Choice(list(SHIELD_KINDS)), default=None,
                     help=SHIELD_HELP),
        click.option("--hv-role", type=click.Choice(list(ROLES)), default=None,
                     help=f"HV initial role [{d.hv.role}]; {KIND_OPTIONS['hv_role'].users()}."),
        click.option("--pa", type=float, default=None,
                     help=f"Human's p_a in [0, 1] [{d.roles.p_a:g}]; "
                          f"{KIND_OPTIONS['pa'].users()}."),
        click.option("--pa-hat", type=PA_HAT, default=None,
                     help="AV's estimate of p_a in [0, 1], or online (a posterior over p_a, "
                          "docs/method.md §13.9) [equal to --pa]; "
                          f"{KIND_OPTIONS['pa_hat'].users()}."),
        scenario_option(f"Geometry [{d.scenario.kind}]", many=True),
        click.option("--seed", type=Count(0, SEED_MAX), default=seed_default,
                     show_default=True, help=seed_help),
    ]

    def decorate(func: Callable) -> Callable:
        func = config_options(func)
        func = junction_options(func)
        for option in reversed(options):
            func = option(func)
        return func

    return decorate


# -- options that only some kinds read ---------------------------------------------------------


@dataclass(frozen=True)
class KindOption:
    """A run option that only some kinds read, and which (``persuasive.policies``)."""

    option: str  #: the option, e.g. "--pa-hat"
    field: str  #: the dotted field it sets
    av_kinds: tuple[str, ...]  #: the AV kinds that read it
    hv_kinds: tuple[str, ...]  #: the human kinds that read it
    what: str  #: what it is to those kinds, for the messages

    def used_by(self, config: Config) -> bool:
        """Whether a kind of ``config`` reads the field."""
        if self.option == "--hv-role" and config.av.kind in self.av_kinds \
                and config.av.role is not None:
            return config.hv.kind in self.hv_kinds  # an LFG AV with its own role ignores it
        return config.av.kind in self.av_kinds or config.hv.kind in self.hv_kinds

    def users(self) -> str:
        """Who reads it, in words: "read only by the lfg, noisy humans and the lfg AV
        (...)"."""
        parts = []
        if self.hv_kinds:
            parts.append(f"the {kinds_text(self.hv_kinds)} human"
                         + ("s" if len(self.hv_kinds) > 1 else ""))
        if self.av_kinds:
            parts.append(f"the {kinds_text(self.av_kinds)} AV"
                         + ("s" if len(self.av_kinds) > 1 else ""))
        return f"read only by {' and '.join(parts)} ({self.what})"


#: The run options only some kinds read (``persuasive.policies.policy_params``), by parameter
#: name:
#:
#: - ``--pa-hat`` (``mpc.p_a_hat``): the persuasive planner's estimate of ``p_a``. The passive
#:   planner carries it but its role transition is the identity whatever it is; no other AV
#:   models the human's ``p_a``.
#: - ``--pa`` (``roles.p_a``): the ``p_a`` of an LFG player of its own: the lfg and noisy
#:   humans and the lfg AV (the stubborn human is the LFG with ``p_a = 0``). Without
#:   ``--pa-hat`` it is also the persuasive AV's estimate, but that alone does not make it
#:   used: the estimate's option is ``--pa-hat``, and a human with no ``p_a`` has none to give.
#: - ``--hv-role`` (``hv.role``): the initial role of the humans that hold one (``has_role`` in
#:   ``policies.kinds``) and, for an LFG AV without ``av.role``, the other role is the AV's
#:   own. The ``lfg-rule`` AV holds a role too, but the traffic rule gives it (neither
#:   option is used by it: its ``p_a`` is 0). Paper mode's quirk Q3 also reads it as the persuasive planner's fallback tie role
#:   against a human without roles; that quirk is no reason to offer the option there.
KIND_OPTIONS: dict[str, KindOption] = {
    "pa_hat": KindOption("--pa-hat", "mpc.p_a_hat", ("persuasive",), (),
                         "its estimate of the human's p_a"),
    "pa": KindOption("--pa", "roles.p_a", tuple(k for k in kinds_with(AV, True)
                                                if k != "lfg-rule"),
                     tuple(k for k in kinds_with(HV, True) if k != "stubborn"),
                     "their own p_a; the persuasive AV's estimate is --pa-hat"),
    "hv_role": KindOption("--hv-role", "hv.role", tuple(k for k in kinds_with(AV, True)
                                                      if k != "lfg-rule"),
                          kinds_with(HV, True),
                          "the lfg AV starts in the other role"),
}


def _who(configs: Sequence[Config]) -> str:
    avs = list(dict.fromkeys(c.av.kind for c in configs))
    hvs = list(dict.fromkeys(c.hv.kind for c in configs))
    return f"the {kinds_text(hvs, sep=' or ')} HV with the {kinds_text(avs, sep=' or ')} AV"


def check_kind_options(options: Mapping[str, Any], configs: Sequence[Config]) -> None:
    """Refuse (:class:`click.UsageError`, exit status 2) each option of :data:`KIND_OPTIONS`
    given in ``options`` (not ``None``) that no kind of any of ``configs`` reads, naming the
    option, the kinds that ignore it and the kinds that read it. ``configs``: every run the
    command makes with these options (``plot profile`` without ``--single`` makes two)."""
    for name, kind_option in KIND_OPTIONS.items():
        value = options.get(name)
        if value is None or any(kind_option.used_by(c) for c in configs):
            continue
        raise click.UsageError(f"{kind_option.option} = {value} is not used by "
                               f"{_who(configs)}; it is {kind_option.users()}")


def unread_options(config: Config) -> list[str]:
    """The options of :data:`KIND_OPTIONS` (``"pa"``, ``"pa_hat"``, ``"hv_role"``) that none of
    ``config``'s kinds reads, set or not. ``roles.p_a`` is read whenever it stands for the
    persuasive AV's estimate (``mpc.p_a_hat`` unset)."""
    estimate = KIND_OPTIONS["pa_hat"].used_by(config) and config.mpc.p_a_hat is None
    return [name for name, kind_option in KIND_OPTIONS.items()
            if not (kind_option.used_by(config) or (name == "pa" and estimate))]


def ignored_fields(config: Config) -> list[str]:
    """The fields of :data:`KIND_OPTIONS` that ``config`` sets away from their defaults but
    that none of its kinds reads (from ``--config`` or ``--set``, which are not refused), as
    ``"mpc.p_a_hat = online"``; for a summary to say that they are ignored."""
    out = []
    for name in unread_options(config):
        section, _, key = KIND_OPTIONS[name].field.partition(".")
        value = getattr(getattr(config, section), key)
        if value != getattr(getattr(_DEFAULTS, section), key):
            out.append(f"{KIND_OPTIONS[name].field} = "
                       f"{value if isinstance(value, str) else f'{value:g}'}")
    return out


def check_workers(workers: int | None, n_tasks: int) -> int:
    """Worker processes for ``n_tasks`` chunks: default all cores, capped at ``n_tasks``.

    More than 8 processes per core is refused (exit 2); more than the cores gets a warning.
    """
    cores = os.cpu_count() or 1
    if workers is None:
        workers = cores
    if workers > 8 * cores:
        raise ConfigError(f"--workers = {workers} is out of range; allowed: 1..{8 * cores} "
                          f"(8 per core, {cores} cores)")
    if workers > cores:
        click.echo(f"warning: {workers} workers on {cores} cores; runs will share the cores",
                   err=True)
    return max(1, min(workers, n_tasks))


def lock_output(path, what: str = "output") -> None:
    """Make this command the only writer of the file or folder ``path`` until it ends
    (:func:`persuasive._files.writer_lock`, released when the command's click context
    closes, also on error): a command writing it already makes this one stop here, in one
    line with exit status 2. Call it once the checks pass, before any work."""
    from .._files import writer_lock

    click.get_current_context().with_resource(writer_lock(path, what))


def check_input_files(*configs: Config) -> None:
    """Read the files the configurations name (the replay human's log, ``hv.replay.file``)
    before any work: a missing or unreadable one is refused at once, in one line, not after
    a compile."""
    from ..policies import load_replay

    for config in configs:
        if config.hv.kind == "replay":
            load_replay(config)


def check_readable(paths: Iterable[str], what: str) -> None:
    """Refuse, in one line naming it, the first of ``paths`` that cannot be opened for reading
    (missing, a folder, no permission): every input file of a command is checked before any
    of them is read and before any compile."""
    for path in paths:
        try:
            with open(path, "rb"):
                pass
        except OSError as exc:
            reason = (exc.strerror or type(exc).__name__).lower()
            raise ConfigError(f"{what} {str(path)!r} cannot be read: {reason}") from None


#: The first line of :func:`compile_notice`, and of :func:`compile_report`'s line.
COMPILE_NOTICE = "compiling the numerical kernels once"
COMPILED = "compiled the numerical kernels in"


def compile_notice(*kernels) -> bool:
    """One line on stderr when the compiled kernels the command uses (default: the closed
    loop's; see :func:`persuasive._compile.kernels_cached`) are not cached yet (first use);
    True when it said so. Call it once the command's inputs are checked: a bad input is
    refused at once, not after a compile."""
    from .._compile import kernels_cached

    if kernels_cached(*kernels):
        return False
    click.echo(f"{COMPILE_NOTICE} (cached for later runs; 'persuasive compile' compiles every "
               "command's)", err=True)
    sys.stderr.flush()
    return True


def junction_compile_notice() -> bool:
    """:func:`compile_notice` for the kernels a junction run uses (``persuasive.many``: the
    pair policies, the shield, the footprint gaps)."""
    from ..policies.step import policy_step_buffers
    from ..safety.measures import footprint_gaps
    from ..safety.shield import shield_filter

    return compile_notice(policy_step_buffers, shield_filter, footprint_gaps)


def compile_report(clock) -> None:
    """One line on stderr when the command compiled kernels (a
    :class:`persuasive._compile.StudyClock` started at its beginning): their time, which the
    time the command prints leaves out."""
    if clock.compile_s > 0.0:
        sys.stdout.flush()
        click.echo(f"{COMPILED} {clock.compile_s:.1f} s (left out of the time reported)",
                   err=True)
        sys.stderr.flush()


def progress_bar(quiet: bool, rows: int | None = None,
                 unit: str = "run") -> Callable[..., None] | None:
    """A progress callback drawing a tqdm bar on stderr (``None`` when ``quiet``):
    ``update(done, total[, rows_done])`` in ``unit`` s, rows shown when ``rows`` is given.

    The bar appears at the first update with runs left (a study resumed with nothing to run
    shows none). ``update.close()`` ends its line: a command calls it when it stops, whether
    it finished or failed, so that an error that follows is printed on a line of its own.
    """
    if quiet:
        return None
    from tqdm import tqdm

    bar: dict[str, Any] = {}

    def update(done: int, total: int, rows_done: int | None = None) -> None:
        if "bar" not in bar:
            if done >= total:
                return  # nothing left to run: no bar
            bar["bar"] = tqdm(total=total, initial=done, unit=unit, file=sys.stderr,
                              dynamic_ncols=True, smoothing=0.1)
        b = bar["bar"]
        if rows is not None and rows_done is not None:
            b.set_postfix_str(f"rows {rows_done}/{rows}", refresh=False)
        b.update(done - b.n)
        if done >= total:
            b.close()

    def close() -> None:
        if "bar" in bar:
            bar["bar"].close()

    update.close = close  # type: ignore[attr-defined]
    return update
