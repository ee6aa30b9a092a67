"""Read the FES workbench's files into pandas: data sets, recordings, model files, .hlog.

Pure Python (pandas; hdrhistogram from PyPI for ``.hlog``). One file: copy it next to
your analysis, or put this directory on ``sys.path``.

    import fes_io
    ds = fes_io.read_dataset("data/fast")          # fes-dataset/1 directory
    ds.records                                     # one row per record: file, kind, samples, pulses, split
    ds.samples                                     # every sample: record, t_ms, pulse, force, force_n (+ decided)
    ds.record(0)                                   # one record's samples
    ds.train(), ds.test()                          # the split's samples
    hs = fes_io.read_dataset("data/heat")          # fes-dataset/2 directory: a SignalSet
    hs.ts_s, hs.inputs, hs.outputs                 # period; channels (name, unit, range_lo, range_hi)
    hs.samples                                     # every sample: record, t_s, then each channel by name
    hs.record(0)["y"], hs.physical("y")            # one channel; in physical units (its range)
    rec = fes_io.read_recording("/var/lib/fes/recordings/2026-12-02T10-00-00Z")
    rec.dataset, rec.streams["ticks"], rec.events  # data set, message streams, events
    m = fes_io.read_model("models/fast.lmn.json")  # fes-lmn/1 or fes-lcn/1
    m.units, m.meta, m.provenance
    h = fes_io.read_hlog("target/bench/rt-core.hlog")  # one row per interval and tag

``read_dataset`` reads either version of the data-set format, as the ``schema`` field of
dataset.json says: ``fes-dataset/1`` (one 0/1 pulse input, normalised force) gives a
``DataSet``, ``fes-dataset/2`` (named continuous input and output channels at any period,
such as the heat-transfer process's) a ``SignalSet``.

Formats: docs/sim-muscle.md (data set /1), crates/fes-dataset/src/signals.rs and
docs/heat-transfer.md (data set /2), docs/supervisor.md (recording), docs/model.md and
docs/control.md (models), crates/fes-rt/src/rt/hlog.rs (.hlog). Every violation of the
data-set formats this reader checks raises FormatError naming the file and line.
"""

from __future__ import annotations

import base64
import json
import math
import os
import re
import struct
import zlib
from dataclasses import dataclass, field

import pandas as pd

__all__ = [
    "FormatError",
    "DataSet",
    "SignalSet",
    "Recording",
    "Model",
    "read_dataset",
    "read_recording",
    "read_model",
    "read_hlog",
    "hlog_histograms",
]

SCHEMA = "fes-dataset/1"
SCHEMA_V2 = "fes-dataset/2"
SCHEMAS = (SCHEMA, SCHEMA_V2)
META_FILE = "dataset.json"
COLUMNS = ["t_ms", "pulse", "force"]
COLUMNS_DECIDED = ["t_ms", "pulse", "force", "decided"]
# The format's rules (fes_dataset): force slack and the time-step tolerance.
FORCE_SLACK = 0.1
TIME_STEP_TOLERANCE = 1e-3
STREAMS = ["ticks", "force", "references", "status", "timing", "beats"]
MODEL_SCHEMAS = ("fes-lmn/1", "fes-lcn/1")


class FormatError(ValueError):
    """A file violates its format; the message names the file and line."""


class _Records:
    """What both data set versions answer from their ``samples`` and ``meta["split"]``."""

    samples: pd.DataFrame
    meta: dict

    def record(self, i: int) -> pd.DataFrame:
        """The samples of record ``i`` (numbered from 0, as in dataset.json)."""
        return self.samples[self.samples["record"] == i].reset_index(drop=True)

    def train(self) -> pd.DataFrame:
        """The samples of the training records."""
        return self.samples[self.samples["record"].isin(self.meta["split"]["train"])]

    def test(self) -> pd.DataFrame:
        """The samples of the test records."""
        return self.samples[self.samples["record"].isin(self.meta["split"]["test"])]


@dataclass
class DataSet(_Records):
    """A fes-dataset/1 data set.

    meta     dataset.json without its record list (schema, source, scale_n, offset_n, ts_s,
             split, ...).
    records  one row per record (index = record number): file, kind, samples, pulses, split
             ("train", "test" or "").
    samples  every sample, records one after another: record, t_ms, pulse (bool), force
             (normalised), force_n (newtons: force * scale_n + offset_n), and decided (bool)
             when the records have that column (a recording of the stimulation chain).
    """

    path: str
    meta: dict
    records: pd.DataFrame
    samples: pd.DataFrame


@dataclass
class SignalSet(_Records):
    """A fes-dataset/2 data set: named continuous channels sampled every ``ts_s`` seconds.

    meta     dataset.json without its record list (schema, source, seed, parameters,
             protocol, ts_s, inputs, outputs, split).
    ts_s     the sample period, s (every record's time base: t_s = t0_s + k * ts_s).
    inputs   one row per input channel, in file order: name, unit, range_lo, range_hi
             (the physical values the stored 0 and 1 stand for; NaN without a range).
    outputs  the same for the output channels.
    records  one row per record (index = record number): file, kind, samples, t0_s, split
             ("train", "test" or "").
    samples  every sample, records one after another: record, t_s, then one column per
             channel named as the channel (inputs first, then outputs), values as stored.
    """

    path: str
    meta: dict
    ts_s: float
    inputs: pd.DataFrame
    outputs: pd.DataFrame
    records: pd.DataFrame
    samples: pd.DataFrame

    @property
    def channels(self) -> list:
        """The channel names, inputs first, as the record files' columns after ``t_s``."""
        return list(self.inputs["name"]) + list(self.outputs["name"])

    def physical(self, name: str, samples: pd.DataFrame | None = None) -> pd.Series:
        """Channel ``name`` of ``samples`` (default: every sample) in physical units:
        range_lo + value * (range_hi - range_lo). A channel without a range is returned
        as stored."""
        frame = self.samples if samples is None else samples
        rows = pd.concat([self.inputs, self.outputs], ignore_index=True)
        row = rows[rows["name"] == name]
        if row.empty:
            raise KeyError(f"no channel `{name}` (channels: {', '.join(self.channels)})")
        lo, hi = float(row["range_lo"].iloc[0]), float(row["range_hi"].iloc[0])
        if math.isnan(lo):
            return frame[name].copy()
        return lo + frame[name] * (hi - lo)


@dataclass
class Recording:
    """A supervisor recording: its data set (None when no record was complete), each
    message stream as a DataFrame (``ticks``, ``force``, ``references``, ``status``,
    ``timing``, ``beats``; those present), and ``events.jsonl`` as a DataFrame."""

    path: str
    dataset: DataSet | None
    streams: dict = field(default_factory=dict)
    events: pd.DataFrame | None = None


@dataclass
class Model:
    """A model file: ``meta`` is the whole JSON; ``units`` one row per unit with every
    list-valued parameter spread over numbered columns (``c_0``, ``c_1``, ...);
    ``provenance`` how it was made. For a controller (fes-lcn/1), ``model`` is the
    embedded fes-lmn/1 model and ``units`` the local controllers."""

    path: str
    schema: str
    meta: dict
    units: pd.DataFrame
    provenance: dict
    model: "Model | None" = None


def _fail(path, line, message):
    where = f"{path}:{line}" if line else f"{path}"
    raise FormatError(f"{where}: {message}")


def _read_text(path):
    with open(path, "rb") as f:
        data = f.read()
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        _fail(path, data[: e.start].count(b"\n") + 1, "not UTF-8 text")
    return text.lstrip("\ufeff")


def _read_record(path, ts_s):
    """Columns of one record file, checked as fes_dataset checks them."""
    lines = _read_text(path).replace("\r\n", "\n").split("\n")
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        _fail(path, 1, "the file is empty")
    header = [c.strip() for c in lines[0].split(",")]
    if header not in (COLUMNS, COLUMNS_DECIDED):
        _fail(path, 1, f"header `{lines[0]}`; expected `{','.join(COLUMNS)}` "
                       f"(or `{','.join(COLUMNS_DECIDED)}`)")
    width = len(header)
    cols = {c: [] for c in header}
    ts_ms = ts_s * 1e3
    prev = None
    for i, line in enumerate(lines[1:], start=2):
        fields = [x.strip() for x in line.split(",")]
        if len(fields) != width:
            _fail(path, i, f"{len(fields)} field(s), expected {width} (as the header)")
        values = []
        for name, text in zip(header, fields):
            try:
                v = float(text)
            except ValueError:
                _fail(path, i, f"field `{name}`: `{text}` is not a number")
            if not math.isfinite(v):
                _fail(path, i, f"field `{name}`: {text} is not finite")
            if name in ("pulse", "decided") and v not in (0.0, 1.0):
                _fail(path, i, f"field `{name}`: `{text}` is not 0 or 1")
            values.append(v)
        t, force = values[0], values[2]
        if t < 0:
            _fail(path, i, f"field `t_ms`: {t} is negative")
        if prev is not None:
            step = t - prev
            if step <= 0:
                _fail(path, i, f"field `t_ms`: {t} does not increase (previous {prev})")
            if abs(step - ts_ms) > TIME_STEP_TOLERANCE * ts_ms:
                _fail(path, i, f"field `t_ms`: step {step} ms differs from ts_s = {ts_ms} ms")
        prev = t
        if not -FORCE_SLACK <= force <= 1 + FORCE_SLACK:
            _fail(path, i, f"field `force`: {force} is outside [{-FORCE_SLACK}, {1 + FORCE_SLACK}]")
        for name, v in zip(header, values):
            cols[name].append(v)
    if len(cols["t_ms"]) < 2:
        _fail(path, 0, f"{len(cols['t_ms'])} sample(s); a record needs at least 2")
    return cols


def read_dataset(path) -> "DataSet | SignalSet":
    """Reads and checks a data-set directory (dataset.json and its record files) of either
    version, as its ``schema`` field says: a ``DataSet`` for fes-dataset/1, a
    ``SignalSet`` for fes-dataset/2."""
    path = os.fspath(path)
    if not os.path.isdir(path):
        raise FormatError(f"data-set directory {path} does not exist or is not a directory")
    meta_path = os.path.join(path, META_FILE)
    try:
        meta = json.loads(_read_text(meta_path))
    except json.JSONDecodeError as e:
        _fail(meta_path, e.lineno, e.msg)
    if not isinstance(meta, dict):
        _fail(meta_path, 0, "not a JSON object")
    schema = meta.get("schema")
    if schema == SCHEMA_V2:
        return _read_signal_set(path, meta_path, meta)
    if schema != SCHEMA:
        expected = ", ".join(f'"{s}"' for s in SCHEMAS)
        _fail(meta_path, 0, f"field `schema` is {json.dumps(schema)}, expected one of {expected}")
    for key in ("scale_n", "offset_n", "ts_s", "split", "records"):
        if key not in meta:
            _fail(meta_path, 0, f"missing field `{key}`")
    ts_s = float(meta["ts_s"])
    if not (math.isfinite(ts_s) and ts_s > 0):
        _fail(meta_path, 0, f"field `ts_s`: {ts_s} is not a sample period > 0 s")
    entries = meta.pop("records")
    n = len(entries)
    if n < 2:
        _fail(meta_path, 0, f"field `records`: {n} record(s); a data set needs at least 2 (train and test)")
    train, test = set(meta["split"]["train"]), set(meta["split"]["test"])
    for which, s in (("train", train), ("test", test)):
        if not s:
            _fail(meta_path, 0, f"field `split.{which}`: the {which} split is empty")
        bad = [i for i in s if not 0 <= i < n]
        if bad:
            _fail(meta_path, 0, f"field `split.{which}`: record index {bad[0]} is out of range (there are {n} records)")
    if train & test:
        _fail(meta_path, 0, f"field `split`: record {min(train & test)} is in both train and test")
    scale, offset = float(meta["scale_n"]), float(meta["offset_n"])
    rows, frames = [], []
    for i, e in enumerate(entries):
        name = e["file"]
        if not name or "/" in name or "\\" in name or name in (".", "..", META_FILE):
            _fail(meta_path, 0, f"field `records[{i}].file`: `{name}` is not a plain file name")
        rpath = os.path.join(path, name)
        cols = _read_record(rpath, ts_s)
        samples, pulses = len(cols["t_ms"]), int(sum(cols["pulse"]))
        if samples != e["samples"]:
            _fail(rpath, 0, f"samples is {samples}, but dataset.json lists {e['samples']}")
        if pulses != e["pulses"]:
            _fail(rpath, 0, f"pulses is {pulses}, but dataset.json lists {e['pulses']}")
        split = "train" if i in train else "test" if i in test else ""
        rows.append({"file": name, "kind": e["kind"], "samples": samples, "pulses": pulses, "split": split})
        frame = pd.DataFrame({
            "record": i,
            "t_ms": cols["t_ms"],
            "pulse": [v == 1.0 for v in cols["pulse"]],
            "force": cols["force"],
        })
        frame["force_n"] = frame["force"] * scale + offset
        if "decided" in cols:
            frame["decided"] = [v == 1.0 for v in cols["decided"]]
        frames.append(frame)
    records = pd.DataFrame(rows, columns=["file", "kind", "samples", "pulses", "split"])
    records.index.name = "record"
    samples = pd.concat(frames, ignore_index=True)
    if "decided" in samples:
        # Records without the column: the pulses are the decisions.
        samples["decided"] = samples["decided"].fillna(samples["pulse"]).astype(bool)
    return DataSet(path=path, meta=meta, records=records, samples=samples)


# fes-dataset/2 (crates/fes-dataset/src/signals.rs): the same checks as its Rust reader.
META_V2_REQUIRED = ("schema", "source", "ts_s", "inputs", "outputs", "split", "records")
META_V2_OPTIONAL = ("seed", "parameters", "protocol")
CHANNEL_FIELDS = ("name", "unit", "range")
ENTRY_V2_FIELDS = ("file", "kind", "samples")
# Rust's f64 syntax (what the Rust reader parses): ASCII digits, no `_` separators.
NUMBER_V2 = re.compile(r"[+-]?(?:(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|inf|infinity|nan)",
                       re.IGNORECASE)


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _is_index(v):
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


def _check_object(meta_path, where, obj, required, optional=()):
    """``obj`` is a JSON object with every ``required`` field and no other than those and
    ``optional`` (the Rust reader's deny_unknown_fields)."""
    if not isinstance(obj, dict):
        _fail(meta_path, 0, f"field `{where}`: not a JSON object")
    prefix = f"{where}." if where else ""
    for key in required:
        if key not in obj:
            _fail(meta_path, 0, f"missing field `{prefix}{key}`")
    for key in obj:
        if key not in required and key not in optional:
            _fail(meta_path, 0, f"unknown field `{prefix}{key}`")


def _check_v2_meta(meta_path, meta):
    """Checks dataset.json of a fes-dataset/2 data set, as the Rust reader does."""
    def bad(field, problem):
        _fail(meta_path, 0, f"field `{field}`: {problem}")

    _check_object(meta_path, "", meta, META_V2_REQUIRED, META_V2_OPTIONAL)
    if not isinstance(meta["source"], str):
        bad("source", "not a string")
    seed = meta.get("seed")
    if seed is not None and not _is_index(seed):
        bad("seed", f"{json.dumps(seed)} is not an unsigned integer")
    params = meta.get("parameters", {})
    if not isinstance(params, dict):
        bad("parameters", "not a JSON object")
    for name, v in params.items():
        if not _is_number(v):
            bad(f"parameters.{name}", f"{json.dumps(v)} is not a number")
    ts_s = meta["ts_s"]
    if not _is_number(ts_s) or not (math.isfinite(ts_s) and ts_s > 0):
        bad("ts_s", f"{json.dumps(ts_s)} is not a sample period > 0 s")
    seen = {"t_s"}
    for which in ("inputs", "outputs"):
        channels = meta[which]
        if not isinstance(channels, list):
            bad(which, "not a list")
        if not channels:
            bad(which, "at least one channel is needed")
        for i, c in enumerate(channels):
            where = f"{which}[{i}]"
            _check_object(meta_path, where, c, CHANNEL_FIELDS[:2], CHANNEL_FIELDS[2:])
            name, unit = c["name"], c["unit"]
            if not isinstance(unit, str):
                bad(f"{where}.unit", "not a string")
            if not isinstance(name, str) or not name or "," in name or any(ch.isspace() for ch in name):
                bad(f"{where}.name", f"`{name}` is not a column name (non-empty, no `,` or spaces)")
            if name in seen:
                bad(f"{where}.name", f"`{name}` repeats (or is `t_s`)")
            seen.add(name)
            rng = c.get("range")
            if rng is not None:
                if not (isinstance(rng, list) and len(rng) == 2 and all(_is_number(x) for x in rng)):
                    bad(f"{where}.range", f"{json.dumps(rng)} is not a pair of numbers")
                lo, hi = rng
                if not (math.isfinite(lo) and math.isfinite(hi) and lo != hi):
                    bad(f"{where}.range", f"[{lo}, {hi}] is not a finite, non-empty range")
    records = meta["records"]
    if not isinstance(records, list):
        bad("records", "not a list")
    for i, e in enumerate(records):
        _check_object(meta_path, f"records[{i}]", e, ENTRY_V2_FIELDS)
        if not isinstance(e["kind"], str):
            bad(f"records[{i}].kind", "not a string")
        if not _is_index(e["samples"]):
            bad(f"records[{i}].samples", f"{json.dumps(e['samples'])} is not a count")
    split = meta["split"]
    _check_object(meta_path, "split", split, ("train", "test"))
    n = len(records)
    if n < 2:
        _fail(meta_path, 0, f"field `records`: {n} record(s); a data set needs at least 2 (train and test)")
    for which in ("train", "test"):
        indices = split[which]
        if not isinstance(indices, list) or not all(_is_index(i) for i in indices):
            bad(f"split.{which}", "not a list of record indices")
        if not indices:
            bad(f"split.{which}", f"the {which} split is empty")
        listed = set()
        for i in indices:
            if i >= n:
                bad(f"split.{which}", f"record index {i} is out of range (there are {n} records)")
            if i in listed:
                bad(f"split.{which}", f"record index {i} repeats")
            listed.add(i)
    both = [i for i in split["train"] if i in split["test"]]
    if both:
        bad("split", f"record {both[0]} is in both train and test")
    files = set()
    for i, e in enumerate(records):
        name = e["file"]
        if (not isinstance(name, str) or not name or name in (".", "..", META_FILE)
                or any(ch in name for ch in "/\\\0")):
            bad(f"records[{i}].file", f"`{name}` is not a plain file name inside the data-set directory")
        if name in files:
            bad(f"records[{i}].file", f"`{name}` is listed twice")
        files.add(name)


def _read_signal_record(path, ts_s, names):
    """Columns of one fes-dataset/2 record file: t_s and the channels ``names``, checked
    as fes_dataset::signals checks them. Blank lines are skipped (line numbers count
    them)."""
    expected = ["t_s"] + names
    lines = _read_text(path).split("\n")
    rows = [(i, l[:-1] if l.endswith("\r") else l) for i, l in enumerate(lines, start=1)]
    rows = [(i, l) for i, l in rows if l.strip()]
    found = rows[0][1] if rows else ""
    if [c.strip() for c in found.split(",")] != expected:
        _fail(path, 1, f"field `header`: `{found}` does not name the channels of dataset.json: "
                       f"expected `{','.join(expected)}`")
    width = len(expected)
    cols = {c: [] for c in expected}
    prev = None
    for i, line in rows[1:]:
        fields = [x.strip() for x in line.split(",")]
        if len(fields) != width:
            _fail(path, i, f"{len(fields)} field(s), expected {width} (as the header)")
        values = []
        for name, text in zip(expected, fields):
            if not NUMBER_V2.fullmatch(text):
                _fail(path, i, f"field `{name}`: `{text}` is not a number")
            v = float(text)
            if not math.isfinite(v):
                _fail(path, i, f"field `{name}`: {text} is not finite")
            values.append(v)
        t = values[0]
        if prev is not None:
            step = t - prev
            if abs(step - ts_s) > TIME_STEP_TOLERANCE * ts_s:
                _fail(path, i, f"field `t_s`: step {step} s differs from ts_s = {ts_s} s")
        prev = t
        for name, v in zip(expected, values):
            cols[name].append(v)
    if len(cols["t_s"]) < 2:
        _fail(path, 0, f"{len(cols['t_s'])} sample(s); a record needs at least 2")
    return cols


def _channel_frame(channels) -> pd.DataFrame:
    rows = []
    for c in channels:
        lo, hi = c.get("range") or (math.nan, math.nan)
        rows.append({"name": c["name"], "unit": c["unit"], "range_lo": float(lo), "range_hi": float(hi)})
    return pd.DataFrame(rows, columns=["name", "unit", "range_lo", "range_hi"])


def _read_signal_set(path, meta_path, meta) -> SignalSet:
    """Reads a fes-dataset/2 directory whose dataset.json is ``meta``."""
    _check_v2_meta(meta_path, meta)
    ts_s = float(meta["ts_s"])
    names = [c["name"] for c in meta["inputs"]] + [c["name"] for c in meta["outputs"]]
    entries = meta.pop("records")
    train, test = set(meta["split"]["train"]), set(meta["split"]["test"])
    rows, frames = [], []
    for i, e in enumerate(entries):
        rpath = os.path.join(path, e["file"])
        cols = _read_signal_record(rpath, ts_s, names)
        samples = len(cols["t_s"])
        if samples != e["samples"]:
            _fail(rpath, 0, f"samples is {samples}, but dataset.json lists {e['samples']}")
        split = "train" if i in train else "test" if i in test else ""
        rows.append({"file": e["file"], "kind": e["kind"], "samples": samples,
                     "t0_s": cols["t_s"][0], "split": split})
        frame = pd.DataFrame({"record": i, **cols}, columns=["record", "t_s"] + names)
        frames.append(frame)
    records = pd.DataFrame(rows, columns=["file", "kind", "samples", "t0_s", "split"])
    records.index.name = "record"
    return SignalSet(path=path, meta=meta, ts_s=ts_s, inputs=_channel_frame(meta["inputs"]),
                     outputs=_channel_frame(meta["outputs"]), records=records,
                     samples=pd.concat(frames, ignore_index=True))


def read_recording(path) -> Recording:
    """Reads a supervisor recording directory: the data set (when dataset.json is there),
    every stream CSV present, and events.jsonl (one JSON object per line)."""
    path = os.fspath(path)
    if not os.path.isdir(path):
        raise FormatError(f"recording directory {path} does not exist or is not a directory")
    dataset = read_dataset(path) if os.path.exists(os.path.join(path, META_FILE)) else None
    streams = {}
    for name in STREAMS:
        p = os.path.join(path, f"{name}.csv")
        if os.path.exists(p):
            streams[name] = pd.read_csv(p)
    events = None
    p = os.path.join(path, "events.jsonl")
    if os.path.exists(p):
        rows = []
        for i, line in enumerate(_read_text(p).split("\n"), start=1):
            if line.strip():
                try:
                    rows.append(json.loads(line))
                except json.JSONDecodeError as e:
                    _fail(p, i, e.msg)
        events = pd.DataFrame(rows)
    return Recording(path=path, dataset=dataset, streams=streams, events=events)


def _units_frame(units) -> pd.DataFrame:
    rows = []
    for u in units:
        row = {}
        for k, v in u.items():
            if isinstance(v, list) and all(isinstance(x, (int, float)) for x in v):
                for j, x in enumerate(v):
                    row[f"{k}_{j}"] = x
            elif isinstance(v, list) and all(isinstance(x, list) for x in v):
                for j, r in enumerate(v):
                    for l, x in enumerate(r):
                        row[f"{k}_{j}_{l}"] = x
            else:
                row[k] = v
        rows.append(row)
    frame = pd.DataFrame(rows)
    frame.index.name = "unit"
    return frame


def _model(path, meta) -> Model:
    schema = meta.get("schema")
    if schema not in MODEL_SCHEMAS:
        _fail(path, 0, f"field `schema` is {json.dumps(schema)}, expected one of {', '.join(MODEL_SCHEMAS)}")
    if not isinstance(meta.get("units"), list):
        _fail(path, 0, "missing field `units` (a list)")
    inner = _model(path, meta["model"]) if schema == "fes-lcn/1" and isinstance(meta.get("model"), dict) else None
    provenance = meta.get("provenance") or (inner.provenance if inner else {})
    return Model(path=path, schema=schema, meta=meta, units=_units_frame(meta["units"]),
                 provenance=provenance, model=inner)


def read_model(path) -> Model:
    """Reads a model file (fes-lmn/1) or a controller file (fes-lcn/1)."""
    path = os.fspath(path)
    try:
        meta = json.loads(_read_text(path))
    except json.JSONDecodeError as e:
        _fail(path, e.lineno, e.msg)
    return _model(path, meta)


def _decode_histogram(payload: str):
    """An interval's histogram. The workbench writes hdrhistogram's uncompressed V2
    encoding; the Python package decodes the compressed one: compress it first."""
    from hdrh.histogram import HdrHistogram

    raw = base64.b64decode(payload)
    (cookie,) = struct.unpack(">I", raw[:4])
    if cookie & ~0xF0 == 0x1C849303:
        z = zlib.compress(raw)
        raw = struct.pack(">II", 0x1C849314, len(z)) + z
    return HdrHistogram.decode(base64.b64encode(raw))


def _hlog_lines(path):
    """(line, tag, start_s, length_s, payload) of every interval of an .hlog file."""
    for i, line in enumerate(_read_text(path).split("\n"), start=1):
        line = line.strip()
        if not line or line.startswith("#") or line.startswith('"'):
            continue
        tag = ""
        if line.startswith("Tag="):
            tag, _, line = line[4:].partition(",")
        parts = line.split(",")
        if len(parts) != 4:
            _fail(path, i, f"{len(parts)} field(s), expected start,length,max,histogram")
        try:
            start, length = float(parts[0]), float(parts[1])
        except ValueError:
            _fail(path, i, "interval start or length is not a number")
        yield i, tag, start, length, parts[3]


def hlog_histograms(path):
    """Every interval of an .hlog file as (tag, start_s, length_s, HdrHistogram)."""
    path = os.fspath(path)
    out = []
    for i, tag, start, length, payload in _hlog_lines(path):
        try:
            out.append((tag, start, length, _decode_histogram(payload)))
        except Exception as e:  # hdrh raises several types
            _fail(path, i, f"cannot decode the histogram: {e!r}")
    return out


def read_hlog(path) -> pd.DataFrame:
    """An HdrHistogram interval log (.hlog, values in ns): one row per interval and tag
    with tag, start_s (since the log's BaseTime), length_s, count, min, mean, p50, p90,
    p99, p999, max."""
    rows = []
    for tag, start, length, h in hlog_histograms(path):
        count = h.get_total_count()
        rows.append({
            "tag": tag,
            "start_s": start,
            "length_s": length,
            "count": count,
            "min": h.get_min_value() if count else 0,
            "mean": h.get_mean_value() if count else 0.0,
            "p50": h.get_value_at_percentile(50.0),
            "p90": h.get_value_at_percentile(90.0),
            "p99": h.get_value_at_percentile(99.0),
            "p999": h.get_value_at_percentile(99.9),
            "max": h.get_max_value() if count else 0,
        })
    return pd.DataFrame(rows, columns=["tag", "start_s", "length_s", "count", "min", "mean",
                                       "p50", "p90", "p99", "p999", "max"])
