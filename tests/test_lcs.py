import numpy as np
import pytest

from adaptive_c3.models.cartpole import CartpoleParams, cartpole_lcs
from adaptive_c3.systems.contact.lcs import Lcs, LcsError, LcsSequence, as_sequence


def _small(**over):
    kw = dict(A=np.eye(2), B=np.ones((2, 1)), D=np.ones((2, 1)), d=np.zeros(2),
              E=np.ones((1, 2)), F=np.eye(1), H=np.zeros((1, 1)), c=np.zeros(1), dt=0.1)
    kw.update(over)
    return Lcs(**kw)


@pytest.mark.parametrize("name,bad", [("A", np.eye(3)), ("B", np.ones((3, 1))),
                                      ("D", np.ones((2, 2))), ("d", np.zeros(3)),
                                      ("E", np.ones((2, 2))), ("F", np.eye(2)),
                                      ("H", np.zeros((1, 2))), ("c", np.zeros(2))])
def test_dimension_errors_name_the_matrix(name, bad):
    with pytest.raises(LcsError, match=f"matrix {name} "):
        _small(**{name: bad})


def test_nonfinite_entries_refused():
    with pytest.raises(LcsError, match="matrix F has non-finite"):
        _small(F=np.array([[np.nan]]))
    with pytest.raises(LcsError, match="x has non-finite"):
        _small().step([np.inf, 0], [0])


def test_immutable():
    lcs = _small()
    with pytest.raises(ValueError):
        lcs.A[0, 0] = 5.0
    with pytest.raises(Exception):
        lcs.A = np.eye(2)


def test_with_residual_shifts_c_only():
    lcs = cartpole_lcs()
    r = np.array([-0.15, 0.15])
    shifted = lcs.with_residual(r)
    np.testing.assert_allclose(shifted.c, lcs.c + r)
    np.testing.assert_array_equal(shifted.E, lcs.E)
    with pytest.raises(LcsError, match="r_comp has 3 entries"):
        lcs.with_residual([0, 0, 0])


def test_wrong_offset_model_is_c_minus_delta_phi():
    dphi = np.array([-0.15, 0.15])
    true, model = cartpole_lcs(), cartpole_lcs(wall_offset_error=dphi)
    np.testing.assert_allclose(true.c, model.c + dphi)
    np.testing.assert_allclose(model.with_residual(dphi).c, true.c)


def test_sequence():
    lcs = cartpole_lcs()
    seq = as_sequence(lcs, 10)
    assert len(seq) == 10 and seq[3] is lcs
    with pytest.raises(LcsError, match="horizon is 5"):
        as_sequence(seq, 5)
    with pytest.raises(LcsError, match="different sizes"):
        LcsSequence((lcs, _small()))


def test_cartpole_hits_right_wall_with_model_sized_force():
    """From x0 = [0.3, 0, 0.3, 0] with no input the pole reaches the right wall.

    While in contact the LCP's slack is zero, so the force is lam = -ks * gap, with
    gap = E x + c the penetration of the active wall; the other wall's force is zero.
    """
    p = CartpoleParams()
    lcs = cartpole_lcs(p)
    x = np.array([0.3, 0.0, 0.3, 0.0])
    hit = None
    for k in range(200):
        x_next, lam = lcs.step(x, [0.0])
        if lam.max() > 0:
            hit = (k, x.copy(), lam.copy())
            break
        x = x_next
    assert hit is not None, "never touched a wall"
    k, xk, lam = hit
    # penetration of the pole tip past the wall: the active row's gap is negative
    gap = lcs.E @ xk + lcs.c
    active = int(np.argmax(lam))
    assert gap[active] < 0
    # the force is exactly what the soft wall implies: lam = -ks * gap
    np.testing.assert_allclose(lam[active], -p.wall_stiffness * gap[active], rtol=1e-9)
    assert lam[1 - active] == 0.0
    # it is the right wall (cart moving right, pole tip at x - l*theta > 0.35)
    assert xk[0] - p.length * xk[1] > p.wall_distance
    assert active == 0   # lambda[0] is the +x (right) wall
    # the force turns the pole so that its tip moves away from the wall (theta_dot up)
    x_next, _ = lcs.step(xk, [0.0])
    x_free = lcs.A @ xk
    assert x_next[3] > x_free[3]


def test_copy_through_abstract_value_stays_read_only():
    from pydrake.common.value import Value
    lcs = cartpole_lcs()
    copied = Value[object](lcs).Clone().get_value()
    with pytest.raises(ValueError):
        copied.F[0, 0] = 1.0
