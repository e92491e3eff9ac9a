"""The paper's Fig. 3 for the cart-pole: where the violation loss gives a gradient.

Over a grid of (cart_x, pole_theta) (velocities 0, u = 0) the true next state comes from
the true cart-pole LCS; the model is the cart-pole with wall offsets wrong by
Delta phi = [-0.15, 0.15]. At each point: l_eps and dl/dr at r = 0 for the model, and the
region: 3 contact and predicted contact, 1 contact only (false negative of the model),
2 predicted only (false positive), 0 neither. `gradient_map_data` returns the arrays,
`make_gradient_map` also draws them (left: regions with the direction of -dl/dr drawn
in the (r_1, r_2) axes, i.e. the direction the learner moves r; right: log10 |dl/dr|, white where it is exactly zero).

Contact only has a thin band of exactly zero gradient next to the true wall (see
`adaptive_c3.systems.learning.violation_loss`): `zero_predicted` marks where the KKT conditions say
the gradient must vanish; it is 3.7 mm of pole-tip travel wide for eps Q_d = 100.
"""
from __future__ import annotations

import numpy as np

from adaptive_c3.models.cartpole import LAMBDA_NAMES, CartpoleParams, cartpole_lcs
from adaptive_c3.systems.learning.violation_loss import prepare_sample, solve_sample

__all__ = ["NEITHER", "CONTACT_ONLY", "PREDICTED_ONLY", "BOTH", "REGION_NAMES",
           "gradient_map_data", "make_gradient_map"]

NEITHER, CONTACT_ONLY, PREDICTED_ONLY, BOTH = 0, 1, 2, 3
REGION_NAMES = {NEITHER: "neither", CONTACT_ONLY: "contact only",
                PREDICTED_ONLY: "predicted only", BOTH: "contact & predicted"}


def gradient_map_data(n_x: int = 120, n_theta: int = 120, x_range=(-0.5, 0.5),
                      theta_range=(-1.0, 1.0), wall_offset_error=(-0.15, 0.15),
                      epsilon: float = 100.0, gamma: float = 1e-2, Qd=None,
                      params: CartpoleParams = CartpoleParams()) -> dict:
    """Arrays of the gradient map, each [n_theta, n_x] (grad: [n_theta, n_x, 2]).

    Keys: cart_x, pole_theta (1-D axes), region, grad, grad_norm, loss, lam_true,
    lam_model, gap_true and gap_model (min_i |q_i| of the true and the model LCS: how far
    a cell is from a region boundary), zero_predicted (the KKT zero-gradient condition),
    kkt (max over grid), epsilon, gamma. (An even number of grid points keeps the
    default grid off the region boundaries.)
    """
    true = cartpole_lcs(params)
    model = cartpole_lcs(params, wall_offset_error=wall_offset_error)
    xs = np.linspace(*x_range, n_x)
    ths = np.linspace(*theta_range, n_theta)
    shape = (n_theta, n_x)
    region = np.zeros(shape, int)
    grad = np.zeros(shape + (2,))
    loss = np.zeros(shape)
    lam_true = np.zeros(shape + (2,))
    lam_model = np.zeros(shape + (2,))
    zero_pred = np.zeros(shape, bool)
    gap_true = np.zeros(shape)
    gap_model = np.zeros(shape)
    kkt = 0.0
    u = np.zeros(model.num_inputs)
    r = np.zeros(model.num_lambda)
    for i, th in enumerate(ths):
        for j, cx in enumerate(xs):
            x = np.array([cx, th, 0.0, 0.0])
            x_next, lt = true.step(x, u)
            lm = model.solve_lambda(x, u)
            s = prepare_sample(x_next, x, u, model, epsilon, gamma, Qd)
            sol = solve_sample(s, r)
            contact, predicted = bool(np.any(lt > 0)), bool(np.any(lm > 0))
            region[i, j] = (CONTACT_ONLY * contact) | (PREDICTED_ONLY * predicted)
            grad[i, j] = sol.grad
            loss[i, j] = sol.loss
            lam_true[i, j], lam_model[i, j] = lt, lm
            qr = s.q + r
            gap_true[i, j] = np.abs(true.complementarity_offset(x, u)).min()
            gap_model[i, j] = np.abs(qr).min()
            zero_pred[i, j] = bool(np.all(qr >= 0) and np.all(qr + s.b >= 0))
            kkt = max(kkt, sol.kkt)
    return dict(cart_x=xs, pole_theta=ths, region=region, grad=grad,
                grad_norm=np.linalg.norm(grad, axis=2), loss=loss, lam_true=lam_true,
                lam_model=lam_model, gap_true=gap_true, gap_model=gap_model,
                zero_predicted=zero_pred, kkt=kkt,
                epsilon=float(epsilon), gamma=float(gamma))


def make_gradient_map(out_png, **kwargs) -> dict:
    """Draw the gradient map to out_png (PNG) and return `gradient_map_data(**kwargs)`."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    data = gradient_map_data(**kwargs)
    xs, ths = data["cart_x"], data["pole_theta"]
    region, grad, gn = data["region"], data["grad"], data["grad_norm"]
    colors = ["#ffffff", "#f4a3a3", "#f7e26b", "#9fd89f"]  # neither, contact, pred, both
    fig, axes = plt.subplots(1, 2, figsize=(12, 5), constrained_layout=True)
    ax = axes[0]
    ax.pcolormesh(xs, ths, region, cmap=ListedColormap(colors), vmin=-0.5, vmax=3.5,
                  shading="nearest")
    step_x = max(1, len(xs) // 15)
    step_t = max(1, len(ths) // 15)
    X, T = np.meshgrid(xs, ths)
    sl = (slice(None, None, step_t), slice(None, None, step_x))
    g = -grad[sl]
    norm = np.linalg.norm(g, axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = np.where(norm[..., None] > 0, g / norm[..., None], 0.0)
    ax.quiver(X[sl], T[sl], unit[..., 0], unit[..., 1], angles="uv", scale=22, width=0.003,
              color="k")
    ax.set_xlabel("cart_x [m]")
    ax.set_ylabel("pole_theta [rad]")
    ax.set_title(f"regions; arrows: direction of -dl/dr in (r[{LAMBDA_NAMES[0]}], "
                 f"r[{LAMBDA_NAMES[1]}])", fontsize=10)
    ax.legend(handles=[Patch(facecolor=c, edgecolor="k", label=REGION_NAMES[k])
                       for k, c in enumerate(colors)], loc="upper left", fontsize=8)
    ax = axes[1]
    with np.errstate(divide="ignore"):
        lg = np.where(gn > 0, np.log10(np.where(gn > 0, gn, 1.0)), np.nan)
    finite = lg[np.isfinite(lg)]
    vmin = np.floor(np.percentile(finite, 1)) if finite.size else None
    mesh = ax.pcolormesh(xs, ths, np.ma.masked_invalid(lg), cmap="viridis",
                         shading="nearest", vmin=vmin)
    ax.contour(xs, ths, region, levels=[0.5, 1.5, 2.5], colors="k", linewidths=0.6)
    fig.colorbar(mesh, ax=ax, label="log10 |dl/dr|  (white: exactly 0)")
    ax.set_xlabel("cart_x [m]")
    ax.set_ylabel("pole_theta [rad]")
    ax.set_title(f"gradient magnitude at r = 0 (eps = {data['epsilon']:g}, "
                 f"gamma = {data['gamma']:g})")
    fig.suptitle("Cart-pole, model wall offsets wrong by [-0.15, 0.15] m "
                 "(velocities 0, u = 0)")
    fig.savefig(out_png, dpi=110)
    plt.close(fig)
    return data


if __name__ == "__main__":
    import sys
    d = make_gradient_map(sys.argv[1] if len(sys.argv) > 1 else "gradient_map.png")
    for k, name in REGION_NAMES.items():
        sel = d["region"] == k
        print(f"{name:22s} cells {sel.sum():5d}  zero-gradient cells "
              f"{np.count_nonzero(d['grad_norm'][sel] == 0):5d}")


def cmd_gradient_map(args) -> int:
    """`adaptive-c3 gradient-map --out DIR`: write the paper's Fig. 3 for the cart-pole."""
    from pathlib import Path
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    make_gradient_map(out / "gradient_map.png")
    print(f"wrote {out / 'gradient_map.png'}")
    return 0
