"""Results of the thesis that its figures do not show, checked cheaply (``python -m bench thesis --only extra_claims``).

Chapter 3 (``extra_claims_ch3``): Prop. 3.2.7 / Cor. 3.2.6 (the ℓ1 minimiser under ``XᵀX = D``), Thm. 3.2.13 (the
weighted soft threshold), Def. 3.2.15 / Rem. 3.2.16 (compressed eigenvalues, modes sorted by them), μ = 0 gives the
eigenfunctions (§3.2.2, for ADMM and the block solver), Ex. 3.3.2 / Thm. 3.3.7 / Cor. 3.3.8 (generalised
manifold harmonics with μ_f = 0 are eigenvectors), Ex. 3.4.10 / Fig. 3.8 (which weights make an affine map an
isometry), Fig. 3.2 (LMHs improve a truncated basis). Chapters 5 and 6 (``extra_claims_ch5_6``): Lemma 5.2.3,
Thm. 5.3.1 and Thm. 5.3.2 under an exact isometry; Table 6.1 and Def. 6.5.1 (the ℓ1 smoothings), Prop. 6.4.24 /
Cor. 6.4.25 (the periodic retraction's π-period). Helpers: ``extra_claims_util``. Fig. 3.3 / §4.3.1 / Fig. 4.6
(LMH orthogonality) need Chapter 4's bases and are in ``chapter3_4_claims``; the Table 7.1 size trend needs its
runs and is in ``chapter7_8_admm``.

Most rows are identities (exact in exact arithmetic): their verdict does not depend on the mesh size, so the quick
run measures the same thing and the default tests compare its verdicts with the committed report's. Meshes:
hand_868 (quick: the generated 642-vertex bumpy example), a generated prism for Ex. 3.4.10; seconds in all.
"""

from __future__ import annotations

from bench.thesis import Claim, Context
from bench.thesis.chapter7_8_util import guarded
from bench.thesis.extra_claims_ch3 import def_3_2_15, ex_3_4_10, fig_3_2, mu_zero, prop_3_2_7, thm_3_2_13, thm_3_3_7
from bench.thesis.extra_claims_ch5_6 import chapter_5_identities, def_6_5_1, prop_6_4_24, table_6_1

__all__ = ["claims", "CHEAP"]

#: the rows the default tests run in quick mode and compare with the committed report (identities, seconds in all;
#: names of the functions imported above)
CHEAP = ("table_6_1", "def_6_5_1", "thm_3_2_13", "prop_3_2_7", "ex_3_4_10", "chapter_5_identities", "prop_6_4_24",
         "thm_3_3_7")


def claims(ctx: Context) -> list[Claim]:
    """Every extra claim, in thesis order; a failed measurement becomes one error row."""
    out: list[Claim] = []
    out += guarded("Fig. 3.2", "LMHs improve a truncated basis", fig_3_2, ctx)
    out += guarded("Prop. 3.2.7, Cor. 3.2.6", "the ℓ1 minimiser under XᵀX = D", prop_3_2_7, ctx)
    out += guarded("§3.2.2 (μ = 0)", "μ = 0 gives the eigenfunctions", mu_zero, ctx)
    out += guarded("Thm. 3.2.13", "the weighted soft threshold", thm_3_2_13, ctx)
    out += guarded("Def. 3.2.15, Rem. 3.2.16", "compressed eigenvalues", def_3_2_15, ctx)
    out += guarded("Ex. 3.3.2, Thm. 3.3.7, Cor. 3.3.8", "GMHs with μ_f = 0", thm_3_3_7, ctx)
    out += guarded("Ex. 3.4.10, Fig. 3.8", "weights and isometry", ex_3_4_10, ctx)
    out += guarded("Lemma 5.2.3, Thms. 5.3.1–5.3.2", "functional-map identities", chapter_5_identities, ctx)
    out += guarded("Prop. 6.4.24, Cor. 6.4.25", "the periodic retraction", prop_6_4_24, ctx)
    out += guarded("Table 6.1", "the ℓ1 smoothings", table_6_1, ctx)
    out += guarded("Def. 6.5.1", "smoothings of the ℓ1 norm", def_6_5_1, ctx)
    return out
