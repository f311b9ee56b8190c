"""The compiled kernels of the preparation and the checks (exubio.model.batch_kernels) against their
numpy and scipy references, to the bit (np.array_equal): they are meant to do the same operations
in the same order, so that the outputs of a trial do not change by a rounding."""
import numpy as np
import pytest
from scipy.signal import butter, filtfilt, lfilter_zi

from exubio.model import batch_kernels as K


@pytest.mark.parametrize("order, cutoff_hz, series", [(2, 2.0, 66), (2, 11.75, 1), (1, 3.0, 7), (3, 5.0, 12),
                                                      (4, 30.0, 3)])
def test_filtfilt_columns_is_scipys_filtfilt_to_the_bit(order, cutoff_hz, series):
    rng = np.random.default_rng(order * 100 + series)
    x = rng.normal(scale=1e-3, size=(1700, series)).cumsum(axis=0) + rng.normal(size=series)
    b, a = butter(order, cutoff_hz, btype="low", fs=200.0)
    want = filtfilt(b, a, x, axis=0, padtype=None)
    got = np.empty_like(x)
    K.filtfilt_columns(b, a, lfilter_zi(b, a), x, got)
    assert np.array_equal(got, want)
    # in place (as exubio.prep.filtering runs it): each row is read before it is written
    y = x.copy()
    K.filtfilt_columns(b, a, lfilter_zi(b, a), y, y)
    assert np.array_equal(y, want)
    # a column's result does not depend on the columns beside it
    one = np.empty((x.shape[0], 1))
    K.filtfilt_columns(b, a, lfilter_zi(b, a), np.ascontiguousarray(x[:, -1:]), one)
    assert np.array_equal(one[:, 0], want[:, -1])


def test_filtfilt_columns_passes_a_constant_and_a_line():
    """A truth neither computes: a zero-lag low-pass keeps a constant, and a line away from the ends
    (where the start from a steady state has died out: 6 cut-off periods, 150 samples)."""
    b, a = butter(2, 4.0, btype="low", fs=100.0)
    t = np.arange(500.0)
    x = np.stack([np.full(500, 0.25), 1e-3 * t], axis=1)
    out = np.empty_like(x)
    K.filtfilt_columns(b, a, lfilter_zi(b, a), x, out)
    assert np.abs(out[:, 0] - 0.25).max() < 1e-12
    assert np.abs(out[150:-150, 1] - x[150:-150, 1]).max() < 1e-12


@pytest.mark.parametrize("b, k, c", [(40, 4, 2), (40, 18, 10), (1, 1, 2), (120, 5, 4), (7, 6, 3)])
def test_chain_normal_equations_are_the_numpy_reference_to_the_bit(b, k, c):
    """(A chain of one coordinate keeps the numpy terms: np.einsum then sums its column in another order.)"""
    from scipy.spatial.transform import Rotation

    from exubio.trust.label_chains import _normal_equations_numpy

    rng = np.random.default_rng(b + k + c)
    rot = Rotation.random(b, random_state=rng.integers(1 << 31)).as_matrix()
    rel, jrel = rng.normal(scale=0.3, size=(b, k, 3)), rng.normal(scale=0.2, size=(b, k, 3, c))
    w = (rng.random((b, k)) > 0.2).astype(float)  # missing markers weigh 0
    e = rng.normal(scale=0.01, size=(b, k, 3)) * w[..., None]
    hess, grad = np.empty((b, 6 + c, 6 + c)), np.empty((b, 6 + c))
    K.chain_normal_equations(rot, rel, jrel, w, e, hess, grad)
    want_hess, want_grad = _normal_equations_numpy(rot, rel, jrel, w, e)
    assert np.array_equal(hess, want_hess) and np.array_equal(grad, want_grad)


@pytest.mark.parametrize("batch", [40, 1])
def test_chain_in_root_frame_is_the_numpy_reference_to_the_bit(batch):
    from exubio.model.kinematics import Kinematics
    from exubio.run.inputs import load_session
    from exubio.trust.label_chains import _ChainModel
    from exubio.trust.label_expectations import expectations_of, marker_points

    exp = expectations_of(load_session().generic_binding)  # the shipped model and protocol's chains
    kin = Kinematics(exp.model)
    points = marker_points(kin, exp.protocol)
    rng = np.random.default_rng(batch)
    for chain in exp.chains:
        cm = _ChainModel(kin, chain, points)
        qc = rng.uniform(-1.0, 1.0, (batch, len(chain.coordinates)))
        got, want = cm.local(qc), cm.local_numpy(qc)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1]), chain.root
        # a truth neither computes: the Jacobian is the derivative of the points in the root frame
        h = 1e-6
        for c in range(len(chain.coordinates)):
            step = np.zeros(len(chain.coordinates))
            step[c] = h
            fd = (cm.local(qc + step)[0] - cm.local(qc - step)[0]) / (2 * h)
            assert np.abs(fd - got[1][..., c]).max() < 1e-7, (chain.root, c)


def test_chain_normal_equations_are_those_of_finite_differences():
    """A truth neither computes: the Jacobian the normal equations are built of is that of the
    residual R(dw) rel(qc) + t - target, checked by central differences (hess = J^T J, grad = J^T e)."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(5)
    k, c = 4, 2
    rot0 = Rotation.random(1, random_state=3).as_matrix()
    t0 = rng.normal(size=3)
    base = rng.normal(scale=0.2, size=(k, 3))
    lin = rng.normal(scale=0.1, size=(k, 3, c))  # rel(qc) = base + lin @ qc: a chain whose points move linearly
    target = rng.normal(scale=0.2, size=(k, 3))

    def res(x):
        r = rot0[0] @ Rotation.from_rotvec(x[:3]).as_matrix()  # the fit's increment: R <- R Rodrigues(dw)
        return (np.einsum("ij,kj->ki", r, base + lin @ x[6:]) + t0 + x[3:6] - target).ravel()

    x0 = np.zeros(6 + c)
    jac = np.stack([(res(x0 + h) - res(x0 - h)) / 2e-6 for h in np.eye(6 + c) * 1e-6], axis=1)
    hess, grad = np.empty((1, 6 + c, 6 + c)), np.empty((1, 6 + c))
    K.chain_normal_equations(rot0, base[None], lin[None], np.ones((1, k)), res(x0).reshape(1, k, 3), hess, grad)
    assert np.allclose(hess[0], jac.T @ jac, atol=1e-8)
    assert np.allclose(grad[0], jac.T @ res(x0), atol=1e-8)


@pytest.mark.parametrize("k", [4, 9, 15, 30])
def test_partner_rms_is_the_numpy_reference_to_the_bit(k):
    from exubio.trust.label_ranges import _error_terms, _partner_rms, _partner_rms_numpy

    rng = np.random.default_rng(k)
    n = 400
    P = rng.normal(scale=0.3, size=(n, k, 3))
    P[rng.random((n, k)) < 0.05] = np.nan  # gaps
    P[:20, 0] = np.nan  # a marker missing in a run of frames
    ref = np.abs(rng.normal(scale=0.3, size=(k, k)))
    ref = ref + ref.T
    ref[0, 1] = ref[1, 0] = np.nan  # never seen together
    pairs = []
    for i in range(k):
        for j in range(i + 1, k):
            pi, pj = rng.random(k) < 0.7, rng.random(k) < 0.7
            pi[[i, j]] = pj[[i, j]] = False
            if pi.any() and pj.any():
                pairs.append((i, j, pi, pj))
    terms = _error_terms(pairs)
    got = _partner_rms(P, ref, *terms)
    assert np.array_equal(got, _partner_rms_numpy(P, ref, *terms), equal_nan=True)
    # a truth neither computes: one term by hand, in plain Python
    f, t = 25, 2
    rows, cols, n_cols, own = terms
    d = [np.sqrt(((P[f, rows[t]] - P[f, c]) ** 2).sum()) - ref[own[t], c] for c in cols[t, :n_cols[t]]]
    d = [x for x in d if np.isfinite(x)]
    assert got[f, t] == pytest.approx(np.sqrt(np.mean(np.square(d))), rel=1e-12)


@pytest.mark.parametrize("B, A, n", [(500, 22, 54), (7, 3, 13), (1, 1, 1)])
def test_quadratic_forms_are_einsums_to_the_bit(B, A, n):
    from exubio.trust.angle_uncertainty import quadratic_forms

    rng = np.random.default_rng(n)
    D = rng.normal(size=(B, A, n))
    L = rng.normal(size=(B, n, n))
    S = L @ np.swapaxes(L, 1, 2)  # covariances
    got = quadratic_forms(D, S)
    assert np.array_equal(got, np.einsum("bai,bij,baj->ba", D, S, D))
    # a truth neither computes: the variance of D x for x ~ N(0, S) is d S d^T, by matrix products
    assert np.allclose(got, np.einsum("bai,bai->ba", D @ S, D), rtol=1e-12, atol=0)


@pytest.mark.parametrize("B, I, J, p", [(500, 3, 3, 6), (9, 5, 2, 6), (2, 1, 1, 4)])
def test_bilinear_blocks_are_einsums_to_the_bit(B, I, J, p):
    from exubio.trust.angle_uncertainty import _bilinear_blocks

    rng = np.random.default_rng(I + J)
    X, Y = rng.normal(size=(B, I, 3, p)), rng.normal(size=(B, J, 3, p))
    S = rng.normal(size=(B, p, p))
    got = _bilinear_blocks(X, S, Y)
    assert np.array_equal(got, np.einsum("bixk,bkl,bjyl->bixjy", X, S, Y))
    want = (X.reshape(B, I * 3, p) @ S @ np.swapaxes(Y.reshape(B, J * 3, p), 1, 2)).reshape(B, I, 3, J, 3)
    assert np.allclose(got, want, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("n, k", [(400, 18), (1, 4), (37, 2)])
def test_pair_distances_are_numpys_norms_to_the_bit_and_layout(n, k):
    from exubio.trust.label_distances import _distances

    rng = np.random.default_rng(n + k)
    pos = rng.normal(scale=0.4, size=(n, k, 3))
    pos[rng.random((n, k)) < 0.05] = np.nan
    iu, ju = np.triu_indices(k, 1)
    want = np.linalg.norm(pos[:, iu, :] - pos[:, ju, :], axis=2)
    got = _distances(pos, iu, ju)
    assert np.array_equal(got, want, equal_nan=True)
    # the medians and SDs are taken over the same layout, so summed alike (a unit axis's stride does not matter)
    assert [st for st, d in zip(got.strides, got.shape) if d > 1] == [st for st, d in zip(want.strides, want.shape) if d > 1]
    a, b = iu[-1], ju[-1]
    ok = np.isfinite(pos[:, [a, b]]).all(axis=(1, 2))
    assert np.allclose(got[ok, -1], [np.sqrt(sum((x - y) ** 2 for x, y in zip(p, q))) for p, q in pos[ok][:, [a, b]]])
