"""The angles CSV with its uncertainty columns is written a block of rows at a time, the angle and
its uncertainty joined per block (no whole-trial copy of the joined table): the file is the same
whatever the block size, and reads back to the values written (issue 38's memory bound)."""
from __future__ import annotations

import numpy as np
import pytest

from exubio.errors import InputError
from exubio.io import results


def _table(n: int, a: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    time = np.arange(n) / 200.0
    q = rng.uniform(-3.0, 3.0, (n, a))
    u = rng.uniform(0.0, 0.1, (n, a))
    q[3, 1], u[5, 0], u[7, 2] = np.nan, np.inf, np.nan  # not measured, not measured at all, no value
    return time, q, u


def test_uncertainty_columns_do_not_depend_on_the_block_size(tmp_path, monkeypatch):
    time, q, u = _table(53, 3)
    names = ["a_deg", "b_deg", "c_deg"]
    one = results.write_angles_csv(tmp_path / "one.csv", time, names, q, comments=["x"], uncertainty_rad=u)
    monkeypatch.setattr(results, "TABLE_BLOCK_ROWS", 7)  # 8 blocks, the last one short
    blocks = results.write_angles_csv(tmp_path / "blocks.csv", time, names, q, comments=["x"], uncertainty_rad=u)
    assert blocks.read_bytes() == one.read_bytes()
    header = blocks.read_text().splitlines()[1]
    assert header == "time_s,a_deg,a_u_deg,b_deg,b_u_deg,c_deg,c_u_deg"
    t_back, names_back, q_back, u_back = results.read_angles_csv(blocks, uncertainty=True)
    assert names_back == tuple(names)
    np.testing.assert_allclose(t_back, time, atol=1e-6)
    np.testing.assert_allclose(np.degrees(q_back), np.degrees(q), atol=1e-6)  # %.6f degrees
    np.testing.assert_allclose(np.degrees(u_back), np.degrees(u), atol=1e-6)
    assert np.isnan(q_back[3, 1]) and np.isinf(u_back[5, 0]) and np.isnan(u_back[7, 2])


def test_uncertainty_of_another_shape_is_refused_naming_the_file(tmp_path):
    time, q, u = _table(10, 3)
    with pytest.raises(InputError, match=r"bad\.csv: uncertainty has shape \(10, 2\)"):
        results.write_angles_csv(tmp_path / "bad.csv", time, ["a", "b", "c"], q, uncertainty_rad=u[:, :2])


def test_mot_further_columns_are_the_joined_table(tmp_path, monkeypatch):
    """The .mot's thorax columns given apart (``more``, joined a block at a time) make the file the
    whole joined table makes, translations (metres) written as they are."""
    time, q, _ = _table(29, 3)
    thorax = np.column_stack([np.linspace(-0.2, 0.3, 29), np.linspace(0.9, 1.1, 29)])
    names = ["a", "b", "c", "pelvis_tilt", "pelvis_tx"]
    joined = results.write_mot(tmp_path / "joined.mot", time, names, np.column_stack([q, thorax]), metres=["pelvis_tx"])
    monkeypatch.setattr(results, "TABLE_BLOCK_ROWS", 4)
    apart = results.write_mot(tmp_path / "apart.mot", time, names, q, more=thorax, metres=["pelvis_tx"])
    assert apart.read_bytes() == joined.read_bytes()
    t_back, names_back, q_back = results.read_mot(apart)
    assert names_back == tuple(names)
    np.testing.assert_allclose(q_back[:, 3], thorax[:, 0], atol=1e-7)  # degrees in the file, radians back
    with pytest.raises(InputError, match=r"bad\.mot: the further columns have shape \(28, 2\)"):
        results.write_mot(tmp_path / "bad.mot", time, names, q, more=thorax[:-1])
