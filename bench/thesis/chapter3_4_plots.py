"""Figures of ``bench.thesis.chapter3_4`` (matplotlib, Agg): each returns a ``Figure`` for
``Context.save_figure``. The mode pictures of Fig. 3.5 come from ``stiefel_cmm.cli.render.grid_sheet``."""

from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["mu_figure", "times_figure", "methods_figure", "sweep_figure", "matrix_figure", "grassmann_figure",
           "basis_reconstruction_figure", "l1_figure", "close"]


def close(fig) -> None:
    plt.close(fig)


def mu_figure(m, fields, mu_labels, table) -> plt.Figure:
    """Fig. 3.5: the modes (rows μ, columns modes) and sparsity / support / energy against μ/n."""
    from PIL import Image

    from stiefel_cmm.cli.render import grid_sheet

    buf = io.BytesIO()
    k = fields[0].shape[1]
    grid_sheet(buf, m.vertices, m.faces, fields, row_titles=mu_labels, col_titles=[f"mode {j + 1}" for j in range(k)],
               dpi=70, panel=1.5)
    img = np.asarray(Image.open(io.BytesIO(buf.getvalue())).convert("RGB"))
    h, w = img.shape[:2]
    fig = plt.figure(figsize=(w / 90 + 0.5, h / 90 + 3.2))
    ax = fig.add_axes([0.0, 3.0 / (h / 90 + 3.2), 1.0, 1.0 - 3.0 / (h / 90 + 3.2)])
    ax.imshow(img)
    ax.axis("off")
    r = [row["mu_over_n"] for row in table]
    for i, (key, name) in enumerate([("sparsity", "sparsity"), ("support_area", "support (area)"),
                                     ("dirichlet", "tr(ΨᵀWΨ)")]):
        a = fig.add_axes([0.07 + i * 0.33, 0.06, 0.25, 2.2 / (h / 90 + 3.2)])
        a.semilogx(r, [row[key] for row in table], "o-")
        a.set_xlabel("μ / n")
        a.set_title(name, fontsize=9)
        if key == "dirichlet":
            a.set_yscale("log")
    return fig


def times_figure(times: dict, extra: dict) -> plt.Figure:
    """Fig. 4.5 for one mesh: seconds per basis type (log scale), with the eigs reference at the LMH count."""
    names = list(times) + list(extra)
    vals = [times[n] for n in times] + [extra[n] for n in extra]
    fig, ax = plt.subplots(figsize=(8, 3.6))
    colors = ["C0" if n in ("LBO", "GL") else "C2" if n.startswith("GLMH") else "C3" if n == "CMM" else "0.6"
              for n in names]
    ax.bar(range(len(names)), vals, color=colors)
    ax.set_yscale("log")
    ax.set_xticks(range(len(names)), names, rotation=60, ha="right", fontsize=8)
    ax.set_ylabel("seconds")
    ax.set_title("time to compute each basis (grey: references)")
    return fig


def methods_figure(families, bases, E: np.ndarray, Em: np.ndarray) -> plt.Figure:
    """Figs. 4.9/4.10: left, LBO's error per family, least squares (filled) vs the product ΦᵀAF (hollow);
    right, product / least squares for every basis and family (1: equal; GL's are all 1). CONSTANT (at
    round-off in every basis but CMM) is left out."""
    keep = [j for j, f in enumerate(families) if f != "CONSTANT"]
    lbo = list(bases).index("LBO")
    fig, (a, b) = plt.subplots(1, 2, figsize=(13, 3.8), gridspec_kw={"width_ratios": [1, 1.6]})
    for x, j in enumerate(keep):
        a.plot(x - 0.1, E[lbo, j], "o", color=f"C{x}")
        a.plot(x + 0.1, Em[lbo, j], "o", mfc="none", color=f"C{x}")
    a.set_yscale("log")
    a.set_xticks(range(len(keep)), [families[j] for j in keep], rotation=45, ha="right", fontsize=8)
    a.set_ylabel("Err(F, R)")
    a.set_title("LBO: filled least squares, hollow ΦᵀAF", fontsize=10)
    width = 0.8 / len(keep)
    for x, j in enumerate(keep):
        b.bar(np.arange(len(bases)) + (x - len(keep) / 2) * width, Em[:, j] / E[:, j], width, color=f"C{x}",
              label=families[j])
    b.axhline(1.0, color="k", lw=0.8)
    b.set_xticks(range(len(bases)), bases, rotation=60, ha="right", fontsize=8)
    b.set_ylabel("Err product / Err least squares")
    b.set_ylim(min(0.9, 0.98 * float(np.min(Em[:, keep] / E[:, keep]))), None)
    b.legend(fontsize=7, ncol=4)
    b.set_title("every basis (GL: Fig. 4.10)", fontsize=10)
    fig.tight_layout()
    return fig


def sweep_figure(sizes, sweep: dict) -> plt.Figure:
    """Fig. 4.11: seconds and mean error against basis size, by method (GLMH bases alone dashed)."""
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6))
    for meth, c in (("lstsq", "C0"), ("manipulation", "C1")):
        a.plot(sizes, sweep[meth]["seconds"], "o-", color=c, label=meth)
        b.plot(sizes, sweep[meth]["error"], "o-", color=c, label=f"{meth}, all bases")
        b.plot(sizes, sweep[meth]["glmh_error"], "s--", color=c, label=f"{meth}, GLMH bases")
    a.set_xlabel("basis size")
    a.set_ylabel("seconds (mean over bases)")
    a.set_yscale("log")
    a.legend(fontsize=8)
    b.set_xlabel("basis size")
    b.set_ylabel("mean Err over families and bases")
    b.set_yscale("log")
    b.legend(fontsize=7)
    fig.tight_layout()
    return fig


def matrix_figure(bases, families, E: np.ndarray) -> plt.Figure:
    """Figs. 4.13/4.14/4.16: log10 errors, the column-scaled matrix (columns sum to 1) and boxplots by basis."""
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(16, 4.6))
    logE = np.log10(np.maximum(E, 1e-16))
    for ax, M, title in ((a, logE, "log10 Err (least squares)"), (b, E / E.sum(axis=0, keepdims=True),
                                                                    "columns scaled to sum 1")):
        im = ax.imshow(M, cmap="hot_r", aspect="auto")
        ax.set_xticks(range(len(families)), families, rotation=45, ha="right", fontsize=8)
        ax.set_yticks(range(len(bases)), bases, fontsize=8)
        ax.set_title(title)
        fig.colorbar(im, ax=ax)
    keep = [j for j, f in enumerate(families) if f != "CONSTANT"]
    c.boxplot([logE[i, keep] for i in range(len(bases))], showmeans=True)
    c.set_xticks(range(1, len(bases) + 1), bases, rotation=60, ha="right", fontsize=8)
    c.set_ylabel("log10 Err per family (CONSTANT left out)")
    c.set_title("by basis type")
    fig.tight_layout()
    return fig


def grassmann_figure(bases, G: np.ndarray, G_thesis: np.ndarray) -> plt.Figure:
    """Fig. 4.17: d_Gr between the bases' spans; left one inner product (A), right GL taken as unit-norm."""
    fig, axes = plt.subplots(1, 2, figsize=(13, 5))
    for ax, M, title in ((axes[0], G, "all bases A-orthonormalised (one inner product)"),
                         (axes[1], G_thesis, "GL eigenvectors of unit Euclidean norm in Lemma 4.6.3")):
        im = ax.imshow(M, cmap="hot_r", vmin=0, vmax=max(float(G.max()), float(G_thesis.max())))
        ax.set_xticks(range(len(bases)), bases, rotation=60, ha="right", fontsize=8)
        ax.set_yticks(range(len(bases)), bases, fontsize=8)
        ax.set_title(title, fontsize=9)
        fig.colorbar(im, ax=ax)
    fig.tight_layout()
    return fig


def basis_reconstruction_figure(curves: dict) -> plt.Figure:
    """Fig. 4.18: red CMMs in the first j LBO eigenfunctions, blue LBO in the first j CMMs; one panel per mesh."""
    fig, axes = plt.subplots(1, len(curves), figsize=(5 * len(curves), 3.6), squeeze=False)
    for ax, (label, (cmm_in_lbo, lbo_in_cmm)) in zip(axes[0], curves.items()):
        j = np.arange(1, len(cmm_in_lbo) + 1)
        ax.plot(j, cmm_in_lbo, "r-", label="CMMs in LBO")
        ax.plot(j, lbo_in_cmm, "b-", label="LBO in CMMs")
        ax.set_xlabel("basis functions used")
        ax.set_ylabel("Err")
        ax.set_title(label, fontsize=9)
        ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def l1_figure(curves: dict) -> plt.Figure:
    """Fig. 4.19: cumulative ‖AΨ_j‖₁ of the CMMs (sorted by compressed eigenvalue) against j."""
    fig, ax = plt.subplots(figsize=(6, 3.6))
    for label, l1 in curves.items():
        ax.plot(np.arange(1, len(l1) + 1), np.cumsum(l1), label=label)
    ax.set_xlabel("number of modes j")
    ax.set_ylabel("‖AΨ_j‖₁ (cumulative)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig
