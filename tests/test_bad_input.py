"""Bad input to the manifold layer raises named, explained errors early."""

import numpy as np
import pytest
import scipy.sparse as sp

from stiefel import (GeneralizedStiefel, NonFiniteError, NotSPDError, RankDeficientError, ShapeError, StiefelError,
                     minimize_sequential)

from stiefel_cases import metric_matrix


@pytest.mark.parametrize("k", [0, -1, 6, 2.5, True, 3.0])
def test_k_out_of_range(k):
    with pytest.raises(ShapeError, match="1 ≤ k ≤ n"):
        GeneralizedStiefel(np.ones(5), k)
    with pytest.raises(ShapeError, match="1 ≤ k ≤ n"):
        minimize_sequential(lambda x: x @ x, np.ones(5), k)


def test_non_spd_metric_in_manifold():
    with pytest.raises(NotSPDError):
        GeneralizedStiefel(np.array([[1.0, 2.0], [2.0, 1.0]]), 1)
    with pytest.raises(NotSPDError):
        GeneralizedStiefel(sp.diags([1.0, -1.0, 1.0]), 1)
    with pytest.raises(NotSPDError):
        minimize_sequential(lambda x: x @ x, np.array([1.0, 0.0, 1.0]), 1)


def test_unknown_names():
    with pytest.raises(StiefelError, match="unknown metric"):
        GeneralizedStiefel(np.ones(4), 2, metric="riemannian")
    with pytest.raises(StiefelError, match="unknown retraction"):
        GeneralizedStiefel(np.ones(4), 2, retraction="exp")
    with pytest.raises(StiefelError, match="unknown direction"):
        minimize_sequential(lambda x: x @ x, np.ones(4), 1, direction="newton")


def test_sequential_start_checks():
    M = metric_matrix("diagonal", 6)
    with pytest.raises(ShapeError, match="X0 must have shape"):
        minimize_sequential(lambda x: x @ x, M, 2, X0=np.ones((6, 3)))
    with pytest.raises(NonFiniteError, match="X0 has 6 non-finite"):
        minimize_sequential(lambda x: x @ x, M, 1, X0=np.full((6, 1), np.nan))
    # two equal start columns: refused where the start enters, with its numerical rank
    with pytest.raises(RankDeficientError, match="numerical rank 1 of k = 2"):
        minimize_sequential(lambda x: x @ x, M, 2, X0=np.ones((6, 2)), max_iters=3)
