"""The grid of a sweep: a base configuration, axes of values, and a range of seeds.

A grid file is TOML with three top-level keys and nothing else::

    seeds = 1000                  # seeds 1..1000; or a table, both ends inclusive:
                                  # [seeds]
                                  # start = 1
                                  # stop = 1000

    [base]                        # a configuration table, as in a config file
    mode = "corrected"
    simulation.n_steps = 61
    [base.mpc]
    epsilon = 0.05

    [axes]                        # dotted field -> list of values
    "roles.p_a" = [0.3, 0.7, 1.0]
    mode = ["paper", "corrected"]

    [[cases]]                     # optional: a list of cases, each a set of overrides
    "av.kind" = "lfg"             # (runs as an axis named ``case`` of values 0, 1, ...,
    [[cases]]                     # the slowest of all: e.g. the rows of a table)
    "mpc.p_a_hat" = 0.95

``[base]`` is read by :meth:`Config.from_dict`; every axis is a dotted field that
:meth:`Config.with_overrides` accepts (``mode``, ``section.field``, ``section.sub.field``).
Unquoted dotted keys in ``[axes]`` (``roles.p_a = [...]``) mean the same as quoted ones.

The runs are the product of the axes times the seeds, in a fixed order: the first axis varies
slowest, the seeds fastest. Run ``r`` is the combination ``r // n_seeds`` (row-major over the
axes) with seed ``start + r % n_seeds``.

The whole grid is validated when it is built: every combination of axis values must give a
valid :class:`Config` (at most :data:`MAX_COMBINATIONS` of them), and the seeds lie in
``[0, 2^32 - 1]``. Every problem raises :class:`ConfigError` with a one-line message that
names the key. Nothing holds a list of the runs: :meth:`Grid.run` and :meth:`Grid.runs` compute
them from their index, so a grid of billions of runs costs no more memory than a small one.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any, Iterator, Mapping

from ..config import Config, ConfigError, read_toml

#: The keys a grid file may hold.
GRID_KEYS = ("seeds", "base", "axes", "cases")
#: The name of the pseudo-axis of a grid's cases.
CASE = "case"
#: Column names of a sweep's dataset that an axis may not take.
RESERVED_COLUMNS = ("run", "seed", "config_hash")
#: Largest seed :func:`persuasive.simulation.simulate` accepts.
SEED_MAX = 2**32 - 1
#: Most combinations of the axes a grid may have: each is built and validated before
#: anything runs (about 0.1 ms each).
MAX_COMBINATIONS = 100_000
#: Combinations whose configurations a grid keeps built (the latest built ones).
_CONFIG_CACHE = 256

_SCALARS = (bool, int, float, str)
_TYPE_NAMES = {bool: "boolean", int: "integer", float: "number", str: "string"}


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _seed_range(value: Any) -> tuple[int, int]:
    """``(start, stop)``, both inclusive, from ``seeds = N`` or a ``[seeds]`` table."""
    if isinstance(value, Mapping):
        for key in value:
            if key not in ("start", "stop"):
                raise ConfigError(f"grid: seeds.{key}: unknown key; allowed: start, stop "
                                  "(both inclusive)")
        for key in ("start", "stop"):
            if key not in value:
                raise ConfigError(f"grid: seeds.{key} is missing; [seeds] needs start and "
                                  "stop (both inclusive)")
            item = value[key]
            if not _is_int(item) or not 0 <= item <= SEED_MAX:
                raise ConfigError(f"grid: seeds.{key} = {item!r} is out of range; allowed: "
                                  f"integer in [0, {SEED_MAX}]")
        start, stop = value["start"], value["stop"]
        if stop < start:
            raise ConfigError(f"grid: seeds.stop = {stop} is out of range; allowed: >= "
                              f"seeds.start = {start} (both inclusive)")
        return start, stop
    if not _is_int(value) or not 1 <= value <= SEED_MAX:
        raise ConfigError(f"grid: seeds = {value!r} is out of range; allowed: integer in "
                          f"[1, {SEED_MAX}] (seeds 1..N), or a [seeds] table with start and "
                          "stop")
    return 1, value


def _flat_axes(table: Mapping[str, Any], prefix: str = "") -> Iterator[tuple[str, Any]]:
    """``[axes]`` as ``(dotted name, value)``; nested tables are unquoted dotted keys."""
    for key, value in table.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            if not value:
                raise ConfigError(f"grid: axes.{name} is an empty table; an axis is a list "
                                  "of values")
            yield from _flat_axes(value, name + ".")
        else:
            yield name, value


def _value_at(data: Mapping[str, Any], dotted: str) -> Any:
    """The value at ``dotted`` in a nested dict, or ``KeyError``."""
    for part in dotted.split("."):
        if not isinstance(data, Mapping):
            raise KeyError(dotted)
        data = data[part]
    return data


def _show(value: Any) -> str:
    return json.dumps(value) if isinstance(value, str) else repr(value)


class Grid:
    """A validated sweep: base configuration, axes and seeds (see the module docstring).

    Build it with :meth:`from_toml` or :meth:`from_dict`. Equal grids (the same base
    configuration, axes and seeds, however written) have equal :attr:`digest`.

    Attributes
    ----------
    base : Config
        The configuration every run starts from.
    axes : tuple of (str, tuple)
        ``(dotted field, values)`` in order; the values as the configuration holds them
        (a TOML integer given for a float field is a float).
    seed_start, seed_stop : int
        The seeds, both inclusive.
    """

    def __init__(self, base: Config, axes: tuple[tuple[str, tuple[Any, ...]], ...],
                 seed_start: int, seed_stop: int, *, cases: tuple[dict[str, Any], ...] = (),
                 _validate: bool = True):
        self.base = base
        self.cases = tuple(dict(c) for c in cases)
        # the cases run as the slowest axis, named "case", of values 0, 1, ...
        self.axes = (((CASE, tuple(range(len(self.cases)))),) if self.cases else ()) + \
            tuple(axes)
        self.seed_start = seed_start
        self.seed_stop = seed_stop
        for name, value in (("seeds.start", seed_start), ("seeds.stop", seed_stop)):
            if not _is_int(value) or not 0 <= value <= SEED_MAX:
                raise ConfigError(f"grid: {name} = {value!r} is out of range; allowed: "
                                  f"integer in [0, {SEED_MAX}]")
        if seed_stop < seed_start:
            raise ConfigError(f"grid: seeds.stop = {seed_stop} is out of range; allowed: >= "
                              f"seeds.start = {seed_start} (both inclusive)")
        self._configs: dict[int, tuple[Config, str]] = {}
        self._digest: str | None = None
        if _validate:
            self.validate()

    # -- building ------------------------------------------------------------------------------

    @classmethod
    def from_toml(cls, path: str | Path, base_overrides: Mapping[str, Any] | None = None
                  ) -> Grid:
        """Read a grid file; a file that cannot be read or parsed is a one-line error.

        ``base_overrides``: dotted fields set in ``[base]`` on top of the file (a command's
        explicit options, e.g. ``persuasive sweep --shield``), refused for a field the grid
        varies."""
        data = read_toml(path, "grid file")
        if base_overrides:
            data = dict(data)
            base = Config.from_dict(data.get("base", {})) if isinstance(
                data.get("base", {}), Mapping) else None
            if base is not None:
                axes = dict(_flat_axes(data.get("axes", {}))) if isinstance(
                    data.get("axes", {}), Mapping) else {}
                for name in base_overrides:
                    if name in axes:
                        raise ConfigError(f"grid: {name} is an axis of {str(path)!r}; an option "
                                          "cannot set it too")
                data["base"] = base.with_overrides(dict(base_overrides)).to_dict()
        return cls.from_dict(data)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Grid:
        """Build from a dict as read from a grid file; validates every combination."""
        if not isinstance(data, Mapping):
            raise ConfigError("grid: must be a table with seeds, [base] and [axes]")
        for key in data:
            if key not in GRID_KEYS:
                raise ConfigError(f"grid: unknown key {key!r}; allowed: "
                                  f"{', '.join(GRID_KEYS)}")
        if "seeds" not in data:
            raise ConfigError("grid: seeds is missing; give seeds = N (seeds 1..N) or a "
                              "[seeds] table with start and stop (both inclusive)")
        start, stop = _seed_range(data["seeds"])
        base_table = data.get("base", {})
        if not isinstance(base_table, Mapping):
            raise ConfigError("grid: base must be a table of configuration sections")
        try:
            base = Config.from_dict(dict(base_table))
        except ConfigError as exc:
            raise ConfigError(f"grid: [base]: {exc}") from None
        axes_table = data.get("axes", {})
        if not isinstance(axes_table, Mapping):
            raise ConfigError("grid: axes must be a table of dotted field = [values]")
        axes = tuple(cls._check_axis(base, name, values)
                     for name, values in _flat_axes(axes_table))
        cases_list = data.get("cases", [])
        if not isinstance(cases_list, list) or not all(isinstance(c, Mapping)
                                                       for c in cases_list):
            raise ConfigError("grid: cases must be a list of tables ([[cases]]) of dotted "
                              "field = value")
        if CASE in dict(axes):
            raise ConfigError(f"grid: axes.{CASE}: {CASE!r} is the name of the cases' axis")
        cases = tuple(dict(_flat_axes(c)) for c in cases_list)
        return cls(base, axes, start, stop, cases=cases)

    @staticmethod
    def _check_axis(base: Config, name: str, values: Any) -> tuple[str, tuple[Any, ...]]:
        """One axis on its own: a non-empty list of distinct scalars of one type, each valid
        on the base configuration. Returns the values as the configuration holds them."""
        if name in RESERVED_COLUMNS:
            hint = " (set the seeds with seeds = N or [seeds])" if name == "seed" else ""
            raise ConfigError(f"grid: axes.{name}: {name!r} cannot be an axis{hint}")
        if not isinstance(values, list):
            raise ConfigError(f"grid: axes.{name} = {_show(values)} is not a list; an axis "
                              "is a list of values, e.g. [0.3, 0.7]")
        if not values:
            raise ConfigError(f"grid: axes.{name} is empty; give at least one value")
        normal = []
        for value in values:
            if not isinstance(value, _SCALARS):
                raise ConfigError(f"grid: axes.{name}: value {_show(value)} is not a number, "
                                  "string or boolean")
            try:
                config = base.with_overrides({name: value})
            except ConfigError as exc:
                raise ConfigError(f"grid: axes.{name} = {_show(value)}: {exc}") from None
            try:
                normal.append(_value_at(config.to_dict(), name))
            except KeyError:
                normal.append(value)
        kinds = {type(v) for v in normal}
        if len(kinds) > 1:
            # an axis is one column of one type (the sweep's dataset, the plots' axes); values
            # of different types, e.g. "online" beside 0.9 for mpc.p_a_hat, are cases
            names = " and ".join(sorted(_TYPE_NAMES.get(k, k.__name__) for k in kinds))
            cases = " ".join(f"[[cases]] {json.dumps(name)} = {_show(v)}" for v in values[:4])
            cases += " ..." if len(values) > 4 else ""
            raise ConfigError(f"grid: axes.{name} mixes value types ({names}); give values "
                              f"of one type, or run each value as a case of its own: {cases} "
                              f"(and no axes.{name})")
        for i, value in enumerate(normal):
            if value in normal[:i]:
                raise ConfigError(f"grid: axes.{name} holds {_show(values[i])} twice; "
                                  "values must be distinct")
        return name, tuple(normal)

    def validate(self) -> None:
        """Build every combination's configuration; :class:`ConfigError` names the first bad
        one, or says that there are more than :data:`MAX_COMBINATIONS`. Called when the grid
        is built."""
        if self.n_combinations > MAX_COMBINATIONS:
            sizes = " x ".join(str(len(values)) for _, values in self.axes)
            raise ConfigError(f"grid: the axes give {self.n_combinations} combinations "
                              f"({sizes}); allowed: at most {MAX_COMBINATIONS}, each is "
                              "validated before anything runs")
        names = self.names
        for i in range(self.n_combinations):
            try:
                self.config(i)
            except ConfigError as exc:
                values = ", ".join(f"{n} = {_show(v)}"
                                   for n, v in zip(names, self.combination(i)))
                raise ConfigError(f"grid: the combination {values} is invalid: {exc}") \
                    from None

    # -- the runs ------------------------------------------------------------------------------

    @property
    def names(self) -> tuple[str, ...]:
        """The axes' dotted fields, in order."""
        return tuple(name for name, _ in self.axes)

    @property
    def seeds(self) -> range:
        """The seeds of every combination."""
        return range(self.seed_start, self.seed_stop + 1)

    @property
    def n_seeds(self) -> int:
        return self.seed_stop - self.seed_start + 1

    @property
    def n_combinations(self) -> int:
        return math.prod(len(values) for _, values in self.axes)

    def __len__(self) -> int:
        """The number of runs: combinations times seeds."""
        return self.n_combinations * self.n_seeds

    def combination(self, index: int) -> tuple[Any, ...]:
        """The axis values of combination ``index`` (row-major: the last axis fastest)."""
        out = []
        for _, values in reversed(self.axes):
            index, j = divmod(index, len(values))
            out.append(values[j])
        return tuple(reversed(out))

    def config(self, index: int) -> Config:
        """The configuration of combination ``index``."""
        return self._config(index)[0]

    def _config(self, index: int) -> tuple[Config, str]:
        cached = self._configs.get(index)
        if cached is None:
            overrides = dict(zip(self.names, self.combination(index)))
            if self.cases:
                overrides = {**self.cases[overrides.pop(CASE)], **overrides}
            config = self.base.with_overrides(overrides)
            if len(self._configs) >= _CONFIG_CACHE:  # bounded: drop the oldest
                del self._configs[next(iter(self._configs))]
            cached = self._configs[index] = (config, config.digest())
        return cached

    def run(self, index: int) -> tuple[dict[str, Any], Config, int]:
        """Run ``index``: ``(axis values by name, configuration, seed)``."""
        if not 0 <= index < len(self):
            raise IndexError(f"run {index} is out of range; the grid has {len(self)} runs")
        combo, offset = divmod(index, self.n_seeds)
        return (dict(zip(self.names, self.combination(combo))), self.config(combo),
                self.seed_start + offset)

    def config_hash(self, index: int) -> str:
        """``Config.digest()`` of run ``index``'s configuration."""
        return self._config(index // self.n_seeds)[1]

    def runs(self) -> Iterator[tuple[dict[str, Any], Config, int]]:
        """Every run in order: ``(axis values by name, configuration, seed)``."""
        for combo in range(self.n_combinations):
            values = dict(zip(self.names, self.combination(combo)))
            config = self.config(combo)
            for seed in self.seeds:
                yield dict(values), config, seed

    # -- identity ------------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """The canonical grid: the whole base configuration, the axes, the seed range.

        ``Grid.from_dict(g.to_dict())`` equals ``g`` (same digest, same runs).
        """
        out = {
            "seeds": {"start": self.seed_start, "stop": self.seed_stop},
            "base": self.base.to_dict(),
            "axes": {name: list(values) for name, values in self.axes if name != CASE or
                     not self.cases},
        }
        if self.cases:
            out["cases"] = [dict(c) for c in self.cases]
        return out

    def to_toml(self) -> str:
        """:meth:`to_dict` as TOML text (axes as quoted dotted keys), canonical."""
        import tomli_w

        return tomli_w.dumps(self.to_dict())

    @property
    def digest(self) -> str:
        """A 16-hex-digit hash of :meth:`to_dict`: the identity of the sweep's runs."""
        if self._digest is None:
            self._digest = self._compute_digest()
        return self._digest

    def _compute_digest(self) -> str:
        data = self.to_dict()
        # the base enters as its canonical TOML so that equal configurations hash equally
        data["base"] = self.base.to_toml() + self.base.resolved_defaults()
        data["axes"] = [[name, list(values)] for name, values in self.axes]
        if self.cases:
            data["cases"] = [sorted(c.items()) for c in self.cases]
        text = json.dumps(data, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Grid) and self.digest == other.digest

    def __hash__(self) -> int:
        return hash(self.digest)

    def __repr__(self) -> str:
        axes = ", ".join(f"{n}: {len(v)}" for n, v in self.axes) or "none"
        return (f"Grid({len(self)} runs: axes {axes}; seeds "
                f"{self.seed_start}..{self.seed_stop}; digest {self.digest})")

    # -- pickling: workers rebuild configurations on demand ------------------------------------

    def __getstate__(self) -> dict[str, Any]:
        return {"base": self.base, "axes": self.axes, "seed_start": self.seed_start,
                "seed_stop": self.seed_stop, "cases": self.cases}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._configs = {}
        self._digest = None


__all__ = ["GRID_KEYS", "Grid", "MAX_COMBINATIONS", "RESERVED_COLUMNS", "SEED_MAX"]
