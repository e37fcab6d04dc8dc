"""The fault catalogue's API cases: invalid options and inputs given to one library call (``stiefel``,
``mesh``, ``objectives``) in a child process, judged by the exception's class and message.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from bench.reliability_harness import ROOT, Case

def _api(expr: str, error: str | None, pattern: str, setup: str = ""):
    """Run ``expr`` in a child: passes when it raises ``error`` (a class name) with ``pattern`` in the message,
    or, for ``error=None``, when it returns."""
    code = (
        "import jax; jax.config.update('jax_enable_x64', True)\n"
        "import numpy as np, scipy.sparse as sp, jax.numpy as jnp\n"
        "import stiefel, mesh, objectives\nfrom stiefel_cmm.cli.demo_mesh import demo_mesh\n"
        f"{setup}\n"
        "try:\n"
        f"    r = {expr}\n    print('RESULT accepted: ' + repr(r)[:160])\n"
        "except Exception as e:\n"
        "    mro = [c.__name__ for c in type(e).__mro__]\n"
        "    print('RESULT ' + type(e).__name__ + ' ' + ','.join(mro) + ' :: ' + ' '.join(str(e).split())[:200])\n"
    )

    def run(tmp: Path) -> tuple[bool, str]:
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        p = subprocess.run([sys.executable, "-c", code], cwd=tmp, env=env, capture_output=True, text=True,
                           timeout=300)
        line = next((ln for ln in p.stdout.splitlines() if ln.startswith("RESULT")), p.stderr.strip()[-200:])
        ok = error is None and line.startswith("RESULT accepted")
        if line.startswith("RESULT ") and not line.startswith("RESULT accepted"):
            name, mro, msg = line[7:].split(" ", 2)[0], line[7:].split(" ", 2)[1], line.split(" :: ", 1)[-1]
            ok = error is not None and error in mro.split(",") and re.search(pattern, msg, re.I) is not None
            line = f"{name}: {msg}"
        return ok, line[:240]
    return run


_SETUP_S = ("S = stiefel.GeneralizedStiefel(np.ones(30), 3)\nf = lambda X: jnp.sum(X ** 2 * jnp.arange(30.)[:, None])\n"
            "X0 = S.random_point(jax.random.PRNGKey(0))\n")
_SETUP_M = "m = mesh.load(demo_mesh(2))\nlap = mesh.laplacian(m)\n"

API_CASES: list[Case] = [
    Case("parameters", "minimize(max_iters=-5)", "StiefelError naming max_iters",
         _api("stiefel.minimize(f, S, X0, max_iters=-5)", "StiefelError", r"max_iters", _SETUP_S)),
    Case("parameters", "minimize(max_iters=True)", "StiefelError naming max_iters",
         _api("stiefel.minimize(f, S, X0, max_iters=True)", "StiefelError", r"max_iters", _SETUP_S)),
    Case("parameters", "minimize(gtol=-1)", "StiefelError naming gtol",
         _api("stiefel.minimize(f, S, X0, gtol=-1.0)", "StiefelError", r"gtol", _SETUP_S)),
    Case("parameters", "minimize(gtol=nan)", "StiefelError naming gtol",
         _api("stiefel.minimize(f, S, X0, gtol=float('nan'))", "StiefelError", r"gtol", _SETUP_S)),
    Case("parameters", "RiemannianCG(S, c1=0.9, c2=0.1)", "StiefelError: 0 < c1 < c2 < 1",
         _api("stiefel.RiemannianCG(S, c1=0.9, c2=0.1)", "StiefelError", r"c1", _SETUP_S)),
    Case("parameters", "RiemannianLBFGS(S, init_step=-1)", "StiefelError naming init_step",
         _api("stiefel.RiemannianLBFGS(S, init_step=-1.0)", "StiefelError", r"init_step", _SETUP_S)),
    Case("parameters", "minimize_sequential(max_iters=0)", "StiefelError naming max_iters",
         _api("stiefel.minimize_sequential(lambda x: x @ x, np.ones(30), 2, max_iters=0)", "StiefelError",
              r"max_iters", _SETUP_S)),
    Case("parameters", "GeneralizedStiefel(M, k=True)", "StiefelError naming k",
         _api("stiefel.GeneralizedStiefel(np.ones(5), True)", "StiefelError", r"\bk\b", _SETUP_S)),
    Case("parameters", "mesh.eigenbasis(lap, k=3.0)", "MeshError naming k (no SystemError from ARPACK)",
         _api("mesh.eigenbasis(lap, 3.0)", "MeshError", r"\bk\b", _SETUP_M)),
    Case("parameters", "mesh.eigenbasis(lap, k=n)", "MeshError naming k < n (no TypeError from scipy)",
         _api("mesh.eigenbasis(lap, lap.W.shape[0])", "MeshError", r"\bk\b", _SETUP_M)),
    Case("parameters", "a NaN in a user Laplacian (eigenbasis)", "named error: non-finite entries",
         _api("mesh.eigenbasis(badlap, 3)",
              "ValueError", r"finite|nan",
              _SETUP_M + "import dataclasses\nbad = lap.W.copy(); bad.data[0] = np.nan\n"
                         "badlap = dataclasses.replace(lap, W=bad)\n")),
    Case("parameters", "a NaN in a user Laplacian (compressed_modes)", "named error: non-finite entries",
         _api("objectives.compressed_modes((bad, lap.A), 3, 1.0)", "ValueError", r"finite|nan",
              _SETUP_M + "bad = lap.W.copy(); bad.data[0] = np.nan\n")),
    Case("parameters", "a rank-deficient start (two equal columns)", "named error: rank-deficient start",
         _api("objectives.compressed_modes(lap, 3, 1.0, start=np.repeat(np.ones((lap.W.shape[0], 1)), 3, 1))",
              "StiefelError", r"rank", _SETUP_M)),
    Case("parameters", "BlockCMM(max_iters=2.5)", "SolverOptionError (a StiefelError) naming max_iters",
         _api("objectives.BlockCMM(max_iters=2.5)", "StiefelError", r"max_iters")),
    Case("parameters", "ADMMCMM(max_iters=0)", "SolverOptionError naming max_iters",
         _api("objectives.ADMMCMM(max_iters=0)", "StiefelError", r"max_iters")),
    Case("mesh", "mesh.load of a non-manifold mesh, allow_nonmanifold=True, robust Laplacian", "works",
         _api("mesh.eigenbasis(mesh.laplacian(mesh.load((np.array([[0,0,0],[1,0,0],[0,1,0],[0,0,1],[.5,-.5,.5]],"
              "float), np.array([[0,2,1],[0,1,3],[0,3,2],[1,2,3],[0,1,4]])), allow_nonmanifold=True), "
              "weights='robust'), 2).evals", None, r"")),
]
