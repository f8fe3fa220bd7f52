"""The public cascaded-tanks benchmark's two records as measured.toml
reads them: estimation.csv (uEst, yEst) and validation.csv (uVal, yVal),
columns pump,level, 1024 samples every 4 s.

    python3 benchmark_records.py PATH/TO/dataBenchmark.csv
"""

import csv
import sys


def main():
    with open(sys.argv[1], newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["uEst"].strip()]
    for name, (u, y) in {"estimation": ("uEst", "yEst"), "validation": ("uVal", "yVal")}.items():
        with open(name + ".csv", "w") as out:
            out.write("pump,level\n")
            for r in rows:
                out.write("%s,%s\n" % (r[u], r[y]))


if __name__ == "__main__":
    main()
