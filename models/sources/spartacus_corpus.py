"""Build exubio/data/spartacus/ from the Spartacus shoulder kinematics dataset.

Source: Moissenet F, Puchaud P, Naaim A, Holzer N, Begon M. Spartacus shoulder kinematics dataset,
J Biomech 2025 (doi 10.1016/j.jbiomech.2025.112642; Zenodo doi 10.5281/zenodo.11455521), its
``spartacus/data`` and ``spartacus/dataset`` folders at commit ec0677c (as copied to
``../shared/reference/spartacus``). Only numbers are taken (published results of the studies, with
their citations in studies.csv); no code of the (GPL-3.0) repository.

Writes, byte for byte where a file is copied:
* ``studies.csv`` = dataset/dataset_of_datasets.csv (per study: citation, method, shoulders,
  frame definitions);
* ``joint_data.csv`` = dataset/dataset_clean_of_joint_data.csv (per curve: joint, sequence,
  plane of elevation, which file holds which rotation);
* ``curves.csv``: every rotation file that joint_data.csv names, as rows folder,file,ht_deg,value_deg
  (the two columns of the file, unchanged; translations are left out);
* ``corrections.csv``: folder,file,factor from each study's corrections.csv (the sign that turns the
  published number into the raw Euler angle of the study's own sequence; applied by exubio.literature.reference).

Run from the project root:  python models/sources/spartacus_corpus.py [../shared/reference/spartacus]
"""
from __future__ import annotations

import csv
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "exubio" / "data" / "spartacus"


def main(src: Path) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src / "dataset" / "dataset_of_datasets.csv", OUT / "studies.csv")
    shutil.copyfile(src / "dataset" / "dataset_clean_of_joint_data.csv", OUT / "joint_data.csv")
    rows = list(csv.DictReader((src / "dataset" / "dataset_clean_of_joint_data.csv").open()))
    wanted = sorted({(r["folder"], r[k]) for r in rows for k in ("dof_1st_euler", "dof_2nd_euler", "dof_3rd_euler")
                     if r[k] and (src / "data" / r["folder"] / r[k]).is_file()})
    missing = sorted({r["folder"] for r in rows if not (src / "data" / r["folder"]).is_dir()})
    with (OUT / "curves.csv").open("w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["folder", "file", "ht_deg", "value_deg"])
        skipped = 0
        for folder, name in wanted:
            for line in (src / "data" / folder / name).read_text(encoding="utf-8").splitlines():
                fields = [v.strip().strip("\x00") for v in line.split(",")[:2]]
                try:
                    ht, val = (float(v) for v in fields)
                except ValueError:  # blank or padding lines of some source files
                    skipped += bool(line.strip())
                    continue
                w.writerow([folder, name, fields[0], fields[1]])
    with (OUT / "corrections.csv").open("w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["folder", "file", "factor"])
        for path in sorted((src / "data").glob("*/corrections.csv")):
            for line in path.read_text(encoding="utf-8").splitlines():
                if line.strip():
                    name, factor = line.split(",")[:2]
                    w.writerow([path.parent.name, name.strip(), factor.strip()])
    print(f"{skipped} non-numeric lines skipped")
    print(f"{len(wanted)} curves from {len({f for f, _ in wanted})} studies; not in the copy: {', '.join(missing)}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT.parent / "shared" / "reference" / "spartacus")
