"""What every command of the command line shares: typed options from dataclass fields
(their docstrings are the help), `--set section.field=value`, list options, the default
folders, and errors as one line. Light on purpose: `bench plot` imports no compute stage."""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import json
import typing
from functools import cache
from pathlib import Path

from bench import ROOT, BenchError
from bench.console import log

LIST_FORM = "one comma-separated list without spaces"
LATEST, QUICK, PUBLISHED = Path("results/latest"), Path("results/quick"), Path("results/published")
"""Default results folders, relative to the current directory. Runs never write to the
published snapshot; only `bench publish` does."""
PHOTOS = "datasets"
"""The published photo sets' folder is `regime_folder(PUBLISHED, PHOTOS)`,
results/published-datasets (`bench publish --to` it; the README states its verdicts)."""
NBV = "nbv"
"""The published next-views snapshot's folder is `regime_folder(PUBLISHED, NBV)`,
results/published-nbv (the README states its chooser's gains)."""
POOLS_RUN = "pools"
"""The published cross-pool snapshot's folder is `regime_folder(PUBLISHED, POOLS_RUN)`,
results/published-pools (`bench run --pools`; the README states its leaders), and the
photo sets' in bags on several pools `regime_folder(PUBLISHED, POOLS_PHOTOS)`."""
POOLS_PHOTOS = "pools-datasets"

REGIMES = {"sparse": (6, "0-4"), "dense": (21, "0,1")}
"""Rig regimes: (views on each scene's path, default seeds). The sparse regime's views are
every fourth of the dense one's (`bench.scenes.catalog.path_positions`), rendered once.
Dense has two seeds: its 21-view units cost three times a sparse unit (2,681 s for the dense
grid on 2 cores, renders cached, against 617 s for the sparse one: docs/speed.md)."""


def regime_folder(base: Path, regime: str) -> Path:
    """A regime's results folder: `base` for the sparse regime, `base`-`regime` else
    (results/latest-dense, results/published-dense)."""
    return base if regime == "sparse" else base.with_name(f"{base.name}-{regime}")


def regime_arg(parser: argparse.ArgumentParser, what: str) -> None:
    parser.add_argument(
        "--regime",
        choices=tuple(REGIMES),
        default=None,
        help=f"rig regime: {', '.join(f'{k} ({v} views, seeds {s})' for k, (v, s) in REGIMES.items())}; "
        f"{what} (default: sparse)",
    )


def published_snapshots() -> list[Path]:
    """The package's published snapshot of each regime that has one (what a dataset run
    compares its ranking with by default)."""
    from bench.results import RUNS

    return [
        ROOT / regime_folder(PUBLISHED, r)
        for r in REGIMES
        if (ROOT / regime_folder(PUBLISHED, r) / RUNS).is_file()
    ]


class Parser(argparse.ArgumentParser):
    """Usage errors as one line, like every other error of the CLI."""

    def error(self, message: str):
        if message.startswith("unrecognized arguments"):
            message += f" (list options take {LIST_FORM}, e.g. --scenes table,facade)"
        self.exit(2, f"bench: error: {message} (see `{self.prog} --help`)\n")


@cache
def field_docs(cls: type) -> dict[str, str]:
    """The docstring written under each field of a dataclass, keyed by field name."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        body = ast.parse(inspect.cleandoc("\n" + inspect.getsource(klass))).body[0].body
        for node, nxt in zip(body, body[1:]):
            if (
                isinstance(node, ast.AnnAssign)
                and isinstance(node.target, ast.Name)
                and isinstance(nxt, ast.Expr)
                and isinstance(nxt.value, ast.Constant)
            ):
                docs[node.target.id] = " ".join(str(nxt.value.value).split())
    return docs


def add_config_args(parser: argparse.ArgumentParser, cls: type, quick=None, choices=None) -> None:
    """One `--option` per dataclass field, its docstring as help and its default shown.
    With a `quick` preset the options default to None (the preset or the class default is
    chosen later, by --quick) and the help names both defaults."""
    docs = field_docs(cls)
    for f in dataclasses.fields(cls):
        kind = (
            {"choices": choices[f.name]} if f.name in (choices or {}) else {"type": type(f.default)}
        )
        if quick is None:
            default, shown = f.default, "%(default)s"
        else:
            default, shown = None, f"{f.default}, or {getattr(quick, f.name)} with --quick"
        parser.add_argument(
            "--" + f.name.replace("_", "-"),
            dest=f.name,
            default=default,
            **kind,
            help=f"{docs.get(f.name, '')} (default: {shown})",
        )


def render_config(args: argparse.Namespace):
    """The render settings of `bench render`, `export` and `gallery`, checked."""
    from bench.render.config import RenderConfig

    return checked_views(config_from_args(RenderConfig, args).validate())


def checked_views(render):
    """`render`, refused in one line above `MAX_VIEWS` views (100000 started rendering)."""
    from bench.render.config import MAX_VIEWS

    if render.views > MAX_VIEWS:
        raise BenchError(f"views must be from 2 to {MAX_VIEWS}, got {render.views}")
    return render


def config_from_args(cls: type, args: argparse.Namespace):
    return cls(
        **{f.name: getattr(args, f.name) for f in dataclasses.fields(cls) if hasattr(args, f.name)}
    )


def parse_list(
    option: str, text: str, kind: type = str, example: str = "", unique: bool = True
) -> tuple:
    """The items of a list option, which has one syntax: `--option a,b,c`. Integer items of
    `--seeds` may also be inclusive ranges such as 100-119. A repeated item runs once,
    unless the list is a vector (`unique` False). Spaces around an item are ignored."""
    how = f"{option} takes {LIST_FORM}, e.g. {option} {example}"
    parts = [x.strip() for x in text.split(",")]
    if not all(parts):
        raise BenchError(f"{how}; got {text!r}")
    items = []
    try:
        for x in parts:
            lo, dash, hi = (
                x.partition("-") if option == "--seeds" and x[1:].count("-") else (x, "", "")
            )
            if dash and int(hi) < int(lo):
                raise BenchError(f"{how}; the range {x} is empty (write it low-high)")
            items += list(range(int(lo), int(hi) + 1)) if dash else [kind(x)]
    except ValueError:
        raise BenchError(f"{how}; {text!r} is not a list of {kind.__name__}") from None
    if not unique:
        return tuple(items)
    unique = tuple(dict.fromkeys(items))
    if len(unique) < len(items):
        repeated = sorted({str(x) for x in items if items.count(x) > 1})
        log(f"{option} repeats {', '.join(repeated)}; each runs once (a repeat is not a replicate)")
    return unique


def _value(text: str, hint, path: str):
    """`text` as a value of the type `hint` (int, float, str, bool, a tuple of them, or
    optional: `none`)."""
    args = typing.get_args(hint)
    if type(None) in args:
        if text.lower() in ("none", ""):
            return None
        hint = next(a for a in args if a is not type(None))
        args = typing.get_args(hint)
    wrong = f"--set {path}={text}: expected"
    if typing.get_origin(hint) is tuple:
        items = text.split(",")
        kinds = [args[0]] * len(items) if args[-1] is Ellipsis else list(args)
        if len(items) != len(kinds):
            raise BenchError(f"{wrong} {len(kinds)} comma-separated values")
        return tuple(_value(x, k, path) for x, k in zip(items, kinds))
    if hint is bool:
        if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
            raise BenchError(f"{wrong} true or false")
        return text.lower() in ("true", "1", "yes")
    if hint in (int, float, str):
        try:
            return hint(text)
        except ValueError:
            raise BenchError(f"{wrong} {hint.__name__}") from None
    raise BenchError(f"--set {path}: a {hint} is not set from the command line")


def _assign(obj, parts: list[str], text: str, path: str):
    """`obj` (a dataclass) with the field at `parts` set from `text`."""
    if obj is None or not dataclasses.is_dataclass(obj):
        raise BenchError(
            f"--set {path}: {'.'.join(path.split('.')[: -len(parts)])} has no settings here"
        )
    names = [f.name for f in dataclasses.fields(obj)]
    if parts[0] not in names:
        raise BenchError(
            f"--set {path}: {type(obj).__name__} has no setting {parts[0]!r}; valid: {', '.join(names)}"
        )
    current = getattr(obj, parts[0])
    if len(parts) > 1:
        value = _assign(current, parts[1:], text, path)
    elif dataclasses.is_dataclass(current):
        inner = ", ".join(f"{parts[0]}.{f.name}" for f in dataclasses.fields(current))
        raise BenchError(f"--set {path}: set its fields ({inner})")
    else:
        value = _value(text, typing.get_type_hints(type(obj))[parts[0]], path)
    return dataclasses.replace(obj, **{parts[0]: value})


def apply_settings(config, assignments: list[str]):
    """`config` with every `section.field=value` of `assignments` applied, in order."""
    for text in assignments:
        path, eq, value = text.partition("=")
        if not eq or not path:
            raise BenchError(
                f"--set takes section.field=value, e.g. backend.ratio=0.7; got {text!r}"
            )
        config = _assign_own(config, path.split("."), value, path) or _assign(
            config, path.split("."), value, path
        )
    return config


def folder_origin(results: Path, commit: str, source=None) -> dict:
    """The origin of the rows of a results folder (`bench.harness.origin.snapshot_origin`),
    under the settings it is bound to, checked against the code of `commit` (read with git,
    or by `source`)."""
    from bench.binding import read_settings
    from bench.harness.origin import snapshot_origin
    from bench.results import RUNS
    from bench.runs import read_runs

    cfg = settings_config(read_settings(results))
    return snapshot_origin(read_runs(Path(results) / RUNS), cfg, commit, source)


def settings_config(settings: dict):
    """The `RunConfig` whose `as_dict` is `settings` (a results folder's `config.json`),
    made as `--set` would make it; one line where no such configuration exists here."""
    from bench.binding import OWN_SETTINGS, flatten
    from bench.render.config import RenderConfig
    from bench.unit import declared  # noqa: F401 (every method's own settings, first)
    from bench.unit.config import RunConfig
    from bench.unit.pooled import SEPARATOR, known

    def text(v) -> str:
        return "none" if v is None else ",".join(map(str, v)) if isinstance(v, list) else str(v)

    config = RunConfig(render=None if settings.get("render") is None else RenderConfig())
    own_of = settings.get(OWN_SETTINGS, {})  # a method declared since has its defaults
    for method in own_of:  # `track-first:aliked`: declared where it is met (a grid on pools)
        if SEPARATOR in method:
            known(method)
    own = {f"{m}.{k}": v for m, d in own_of.items() for k, v in d.items()}
    shared = {k: v for k, v in settings.items() if k != OWN_SETTINGS and v is not None}
    config = apply_settings(config, [f"{k}={text(v)}" for k, v in (flatten(shared) | own).items()])
    made = json.loads(json.dumps(config.as_dict()))
    made[OWN_SETTINGS] = {m: v for m, v in made[OWN_SETTINGS].items() if m in own_of}
    if made != settings:
        raise BenchError("these settings are not this bench's: `bench upgrade` the folder first")
    return config


def _assign_own(config, parts: list[str], text: str, path: str):
    """`config` (a `RunConfig`) with a method's own setting set (`method.field=value`),
    or None if `path` names no method with settings of its own."""
    from bench.vocabulary import SETTINGS

    if not hasattr(config, "with_own"):
        return None
    if parts[0] == "policy" and len(parts) == 2:  # a setting that moved to its method
        owner = [m for m, cls in SETTINGS.items() if parts[1] in config.own(m)]
        if owner:
            raise BenchError(
                f"--set {path}: {parts[1]} is {owner[0]}'s own setting: "
                f"--set {owner[0]}.{parts[1]}={text}"
            )
    if parts[0] not in SETTINGS or len(parts) != 2:
        return None
    own = _assign(config.policy_config(parts[0]), parts[1:], text, path)
    try:
        return config.with_own(parts[0], **{parts[1]: getattr(own, parts[1])})
    except BenchError as e:
        raise BenchError(f"--set {path}: {e}") from None


def settings_help(cls: type, prefix: str = "") -> list[str]:
    """`section.field` of every setting of a (nested) dataclass, for `--set`'s help."""
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        if typing.get_origin(hints[f.name]) is dict:  # the methods' own: `methods_help`
            continue
        inner = [
            a
            for a in (hints[f.name], *typing.get_args(hints[f.name]))
            if dataclasses.is_dataclass(a)
        ]
        out += settings_help(inner[0], f"{prefix}{f.name}.") if inner else [f"{prefix}{f.name}"]
    return out


def settings_arg(parser: argparse.ArgumentParser, help: str) -> None:
    """`--set SECTION.FIELD=VALUE` (repeatable), into `args.settings` (`apply_settings`)."""
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        dest="settings",
        metavar="SECTION.FIELD=VALUE",
        help=help,
    )


def folder(text: str) -> Path:
    """A folder option's value, refused where a file stands in its place or in its path's."""
    path = Path(text)
    for p in (path, *path.parents):
        if p.exists():
            if not p.is_dir():
                where = "" if p == path else f" in {path}"
                raise argparse.ArgumentTypeError(f"{p}{where} is a file; give a folder")
            break
    return path


def renders_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--renders",
        type=folder,
        default=ROOT / "renders",
        help=f"render cache directory (default: {ROOT / 'renders'})",
    )


def training_args(parser: argparse.ArgumentParser, out: Path, what: str) -> None:
    """The options of a training command: its seeds, scene types, output file (`out`, the
    one shipped with the package; `what` names it) and render cache."""
    from bench.scenes.spec import scene_names

    parser.add_argument("--seeds", default="100-102", help="training seeds (default: %(default)s)")
    parser.add_argument(
        "--scenes", default=",".join(scene_names()), help="scene types (default: %(default)s)"
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=out,
        help=f"{what} (default: the one shipped with the package, %(default)s)",
    )
    renders_arg(parser)


def training_grid(args: argparse.Namespace) -> tuple[list[str], list[int]]:
    """The checked scene types and seeds of a training command."""
    from bench.scenes.spec import load_spec

    seeds = parse_list("--seeds", args.seeds, int, "100-119")
    scenes = parse_list("--scenes", args.scenes, str, "table,facade")
    for s in scenes:
        load_spec(s)
    return list(scenes), list(seeds)


def results_arg(parser: argparse.ArgumentParser, default: Path | None, what: str) -> None:
    parser.add_argument("--results", type=folder, default=default, help=what)


def snapshot_pools(rows) -> list[str]:
    """The pools of a snapshot's rows (`bench.frontend.pools.PoolSpec`: `sift`,
    `aliked+ratio`), in order of first appearance; none for rows from before pools."""
    from bench.frontend.pools import PoolSpec

    if "pool" not in rows:
        return []
    pairs = rows.loc[rows["pool"].fillna("") != "", ["pool", "matcher"]].drop_duplicates()
    return [str(PoolSpec(p, m)) for p, m in pairs.itertuples(index=False)]


def snapshot_grid(snapshot: Path, rows) -> list[str]:
    """`bench run` options that repeat a snapshot's grid and settings on `rows` (a slice of
    its rows): its scenes, seeds, budgets, tasks, protocols and, where they are several,
    pools, and for a rendered one its render settings (its config.json; a dataset's rows
    need their --dataset folders)."""
    from bench.binding import read_settings

    render = read_settings(Path(snapshot))["render"]
    protocols = sorted(set(rows["protocol"]) - {"none"})
    out = ["--budget", ",".join(str(b) for b in sorted(set(rows["budget"]) - {0}))]
    out += ["--tasks", ",".join(sorted(set(rows["task"])))]
    out += ["--protocols", ",".join(protocols)] if protocols else []
    pools = snapshot_pools(rows)
    out += ["--pools", ",".join(pools)] if len(pools) > 1 else []
    if render is None:
        return out
    out += ["--scenes", ",".join(sorted(set(rows["scene"])))]
    out += ["--seeds", ",".join(str(s) for s in sorted(set(rows["seed"])))]
    for name in ("views", "width", "height", "spp", "max_depth", "denoise", "variant"):
        out += [f"--{name.replace('_', '-')}", str(render[name])]
    return out
