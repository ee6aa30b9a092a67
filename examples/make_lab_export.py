"""Writes examples/lab-export.csv: a sim-muscle data set as another lab's rig would export it.

    target/release/sim-muscle record --preset fast --records 20 --train-records 10 \
        --seed 7 --out target/example-sim
    python3 examples/make_lab_export.py target/example-sim examples/lab-export.csv

One table, the records one after another with a 1 s rest between them: `time_s` (seconds,
one clock for the whole session), `force_N` (raw sensor force in newtons: the offset is
not removed, nothing is normalised) and `stim` (1 in the sample where a pulse starts). The
README's "Use your own data" imports it with `fes dataset import`.
"""

import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
import fes_io  # noqa: E402

REST_S = 1.0


def main(src, out):
    ds = fes_io.read_dataset(src)
    start = 0.0
    with open(out, "w") as f:
        f.write("time_s,force_N,stim\n")
        for i in range(len(ds.records)):
            rec = ds.record(i)
            for t_ms, force_n, pulse in zip(rec["t_ms"], rec["force_n"], rec["pulse"]):
                f.write(f"{start + t_ms / 1e3:.3f},{force_n:.3f},{int(pulse)}\n")
            start += rec["t_ms"].iloc[-1] / 1e3 + REST_S


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
