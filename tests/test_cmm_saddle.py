"""BlockCMM's saddle checks (objectives.cmm.saddle): on the small bumpy sphere the solve from the eigenbasis alone
without them stops on a saddle's plateau; with them it steps off along negative curvature and ends lower."""

from __future__ import annotations

import pytest

import mesh
from objectives.cmm.modes import compressed_modes, first_eigenpairs, unpack_laplacian
from objectives.cmm.solvers import ADMMCMM, BlockCMM, SolverOptionError

K = 10


@pytest.fixture(scope="module")
def problem():
    W, a = unpack_laplacian(mesh.laplacian(mesh.example("bumpy", size=-1)))
    pairs = first_eigenpairs(W, a, K)
    return W, a, pairs, 2.0 * float(pairs[0][-1])


@pytest.mark.slow
def test_saddle_check_escapes_the_plateau(problem):
    W, a, pairs, mu = problem
    # from the eigenbasis alone (starts=1): the default's screen of rotated starts does not pick this plateau's start
    plain = compressed_modes((W, a), K, mu, solver=BlockCMM(saddle_checks=0, starts=1), eigenpairs=pairs, finish=None)
    checked = compressed_modes((W, a), K, mu, solver=BlockCMM(starts=1), eigenpairs=pairs, finish=None)
    admm = compressed_modes((W, a), K, mu, solver=ADMMCMM(), eigenpairs=pairs, finish=None)
    assert "saddles" not in plain.params
    records = checked.params["saddles"]
    escapes = [r for r in records if r["step"] > 0]
    assert escapes and escapes[0]["curvature"] < -1e-3 * float(pairs[0][-1]) and escapes[0]["decrease"] > 0
    assert records[-1]["step"] == 0.0 and records[-1]["curvature"] > 0  # ended where no escape was found
    assert checked.status == "converged" and checked.orthogonality < 1e-12
    assert checked.objective < 0.97 * plain.objective  # measured: 1595.3 vs 1675.6
    assert checked.objective <= 1.001 * admm.objective
    screened = compressed_modes((W, a), K, mu, solver=BlockCMM(saddle_checks=0), eigenpairs=pairs, finish=None)
    # the screen alone (no checks) does not pick the plateau's start: measured 1594.30, ADMM 1594.46
    assert "saddles" not in screened.params and screened.objective <= 1.001 * admm.objective


def test_saddle_options_are_validated():
    for bad in (dict(saddle_checks=-1), dict(saddle_checks=1.5), dict(saddle_ftol=-1e-5),
                dict(saddle_tol=float("nan"))):
        with pytest.raises(SolverOptionError, match="saddle"):
            BlockCMM(**bad)
