"""Tests of fes_io against files the workbench wrote.

    python3 python/test_fes_io.py EXPECT.json

EXPECT.json (written by workbench/tests/it/readers.rs, which runs this script) names a
data set, a recording, model files and an .hlog, with what the Rust side knows of each.
Plain unittest: needs pandas and hdrhistogram (scripts/setup installs them).
"""

import json
import math
import os
import sys
import tempfile
import unittest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import fes_io  # noqa: E402

EXPECT = {}


class DataSetTest(unittest.TestCase):
    def test_records_samples_and_split(self):
        e = EXPECT["dataset"]
        ds = fes_io.read_dataset(e["dir"])
        self.assertEqual(list(ds.records["file"]), [r["file"] for r in e["records"]])
        self.assertEqual(list(ds.records["kind"]), [r["kind"] for r in e["records"]])
        self.assertEqual(ds.meta["split"], e["split"])
        self.assertEqual(ds.meta["scale_n"], e["scale_n"])
        for i, r in enumerate(e["records"]):
            rec = ds.record(i)
            self.assertEqual(len(rec), r["samples"])
            self.assertEqual(int(rec["pulse"].sum()), r["pulses"])
            self.assertEqual(list(rec["force"]), r["force"], "exact: shortest round-trip numbers")
            self.assertEqual([k for k, p in enumerate(rec["pulse"]) if p], r["pulse_at"])
            self.assertEqual(list(rec["t_ms"]), [k * (e["ts_s"] * 1e3) for k in range(r["samples"])])
            for f, fn in zip(rec["force"], rec["force_n"]):
                self.assertAlmostEqual(fn, f * e["scale_n"] + e["offset_n"], places=9)
            if r["decided_at"] is not None:
                self.assertEqual([k for k, d in enumerate(rec["decided"]) if d], r["decided_at"])
            else:
                self.assertEqual(list(rec["decided"]), list(rec["pulse"]))
        self.assertEqual(list(ds.records["split"]),
                         ["train" if i in e["split"]["train"] else "test" for i in range(len(e["records"]))])
        self.assertEqual(len(ds.train()) + len(ds.test()), len(ds.samples))

    def test_violations_name_file_and_line(self):
        e = EXPECT["dataset"]
        with tempfile.TemporaryDirectory() as d:
            for name in os.listdir(e["dir"]):
                with open(os.path.join(e["dir"], name), "rb") as src, open(os.path.join(d, name), "wb") as dst:
                    dst.write(src.read())
            first = e["records"][0]["file"]
            path = os.path.join(d, first)
            with open(path) as f:
                lines = f.read().split("\n")
            fields = lines[3].split(",")
            fields[2] = "abc"
            lines[3] = ",".join(fields)
            with open(path, "w") as f:
                f.write("\n".join(lines))
            with self.assertRaises(fes_io.FormatError) as cm:
                fes_io.read_dataset(d)
            self.assertEqual(str(cm.exception), f"{path}:4: field `force`: `abc` is not a number")
            meta = os.path.join(d, "dataset.json")
            with open(meta) as f:
                m = json.load(f)
            m["schema"] = "fes-dataset/3"
            with open(meta, "w") as f:
                json.dump(m, f)
            with self.assertRaises(fes_io.FormatError) as cm:
                fes_io.read_dataset(d)
            self.assertIn('field `schema` is "fes-dataset/3", expected one of "fes-dataset/1", "fes-dataset/2"',
                          str(cm.exception))
            # A version-1 data set relabelled as version 2 is read as version 2: refused.
            m["schema"] = "fes-dataset/2"
            with open(meta, "w") as f:
                json.dump(m, f)
            with self.assertRaises(fes_io.FormatError) as cm:
                fes_io.read_dataset(d)
            self.assertEqual(str(cm.exception), f"{meta}: missing field `inputs`")


class SignalSetTest(unittest.TestCase):
    """fes-dataset/2: the heat-transfer experiments as sim-heat wrote them."""

    def test_channels_by_name_with_their_time_base(self):
        e = EXPECT["signals"]
        ds = fes_io.read_dataset(e["dir"])
        self.assertIsInstance(ds, fes_io.SignalSet)
        self.assertEqual(ds.meta["schema"], "fes-dataset/2")
        self.assertEqual(ds.meta["source"], e["source"])
        self.assertEqual(ds.meta["seed"], e["seed"])
        self.assertEqual(ds.meta["split"], e["split"])
        self.assertEqual(ds.ts_s, e["ts_s"])
        for frame, channels in ((ds.inputs, e["inputs"]), (ds.outputs, e["outputs"])):
            self.assertEqual(list(frame["name"]), [c["name"] for c in channels])
            self.assertEqual(list(frame["unit"]), [c["unit"] for c in channels])
            self.assertEqual([[lo, hi] for lo, hi in zip(frame["range_lo"], frame["range_hi"])],
                             [c["range"] for c in channels])
        names = [c["name"] for c in e["inputs"] + e["outputs"]]
        self.assertEqual(ds.channels, names)
        self.assertEqual(list(ds.samples.columns), ["record", "t_s"] + names)
        self.assertEqual(list(ds.records["file"]), [r["file"] for r in e["records"]])
        self.assertEqual(list(ds.records["kind"]), [r["kind"] for r in e["records"]])
        self.assertEqual(list(ds.records["split"]),
                         ["train" if i in e["split"]["train"] else "test" if i in e["split"]["test"] else ""
                          for i in range(len(e["records"]))])
        ranges = {c["name"]: c["range"] for c in e["inputs"] + e["outputs"]}
        for i, r in enumerate(e["records"]):
            rec = ds.record(i)
            self.assertEqual(len(rec), r["samples"])
            self.assertEqual(ds.records["samples"][i], r["samples"])
            self.assertEqual(ds.records["t0_s"][i], r["t0_s"])
            # The writer's times, t0 + k * ts, exactly (shortest round-trip numbers).
            self.assertEqual(list(rec["t_s"]), [r["t0_s"] + k * e["ts_s"] for k in range(r["samples"])])
            for name in names:
                self.assertEqual(list(rec[name]), r["values"][name], f"{r['file']} {name}: exact")
                lo, hi = ranges[name]
                phys = ds.physical(name, rec)
                for v, p in zip(r["values"][name][:50], phys[:50]):
                    self.assertAlmostEqual(p, lo + v * (hi - lo), places=9)
        train_records = set(ds.train()["record"])
        self.assertEqual(train_records, set(e["split"]["train"]))
        self.assertEqual(set(ds.test()["record"]), set(e["split"]["test"]))
        self.assertEqual(len(ds.train()) + len(ds.test()), len(ds.samples))
        with self.assertRaises(KeyError):
            ds.physical("force")

    def test_every_violation_the_rust_reader_refuses(self):
        cases = EXPECT["violations"]
        self.assertEqual(len(cases), 27)
        for case in cases:
            with self.subTest(case["name"]):
                with self.assertRaises(fes_io.FormatError) as cm:
                    fes_io.read_dataset(case["dir"])
                message = str(cm.exception)
                self.assertIn(case["dir"], message)
                for text in case["expect"]:
                    self.assertIn(text, message)


class RecordingTest(unittest.TestCase):
    def test_streams_events_and_data_set(self):
        e = EXPECT["recording"]
        rec = fes_io.read_recording(e["dir"])
        self.assertEqual(len(rec.streams["ticks"]), e["ticks"])
        self.assertEqual(len(rec.streams["force"]), e["force_samples"])
        self.assertEqual(list(rec.streams["ticks"]["pulse"][:e["ticks"]]), e["tick_pulses"])
        self.assertTrue(math.isclose(rec.streams["force"]["force"].sum(), e["force_sum"], rel_tol=1e-12))
        self.assertEqual(len(rec.dataset.records), e["records"])
        self.assertEqual(list(rec.dataset.records["samples"]), e["record_samples"])
        self.assertEqual(len(rec.events), e["events"])
        self.assertIn(e["event_text"], " ".join(str(v) for v in rec.events.iloc[-1].values))


class ModelTest(unittest.TestCase):
    def test_lmn_and_lcn(self):
        e = EXPECT["models"]
        m = fes_io.read_model(e["lmn"])
        self.assertEqual(m.schema, "fes-lmn/1")
        self.assertEqual(len(m.units), e["lmn_units"])
        self.assertEqual(list(m.units["eigenvalues_0"]), e["eigenvalues_0"])
        self.assertEqual(m.meta["structure"], e["structure"])
        self.assertIn("train_msse", m.provenance)
        c = fes_io.read_model(e["lcn"])
        self.assertEqual(c.schema, "fes-lcn/1")
        self.assertEqual(c.model.schema, "fes-lmn/1")
        self.assertEqual(len(c.units), e["lcn_units"])
        with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
            f.write('{"schema": "fes-lmn/9", "units": []}')
        try:
            with self.assertRaises(fes_io.FormatError):
                fes_io.read_model(f.name)
        finally:
            os.unlink(f.name)


class HlogTest(unittest.TestCase):
    def test_intervals(self):
        e = EXPECT["hlog"]
        h = fes_io.read_hlog(e["path"])
        self.assertEqual(list(h["tag"]), [i["tag"] for i in e["intervals"]])
        self.assertEqual(list(h["count"]), [i["count"] for i in e["intervals"]])
        self.assertEqual(list(h["max"]), [i["max"] for i in e["intervals"]])
        self.assertEqual(list(h["p50"]), [i["p50"] for i in e["intervals"]])
        self.assertEqual(list(h["start_s"]), [i["start_s"] for i in e["intervals"]])


if __name__ == "__main__":
    with open(sys.argv[1]) as f:
        EXPECT.update(json.load(f))
    unittest.main(argv=[sys.argv[0], "-v"])
