"""The shipped example trial is exubio's own output: regenerating it gives the same files."""
import numpy as np

from exubio.cli import EXAMPLE_COMMAND, main
from exubio.io.c3d import read_c3d
from exubio.io.results import read_angles_csv
from exubio.io.resources import shipped_file


def test_shipped_example_is_reproduced_by_its_command(tmp_path):
    shipped = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")
    args = EXAMPLE_COMMAND.split()[1:]
    args[args.index("--out") + 1] = str(tmp_path / "example_abduction.c3d")
    assert main(args) == 0
    a, b = read_c3d(shipped), read_c3d(tmp_path / "example_abduction.c3d")
    assert a.labels == b.labels and a.rate_hz == b.rate_hz == 100.0
    assert np.array_equal(a.positions_m, b.positions_m)
    ta, na, qa = read_angles_csv(shipped.with_name("example_abduction.truth.csv"))
    tb, nb, qb = read_angles_csv(tmp_path / "example_abduction.truth.csv")
    assert na == nb and np.array_equal(qa, qb) and np.array_equal(ta, tb)
