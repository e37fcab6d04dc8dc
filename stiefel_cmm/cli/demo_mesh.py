"""The built-in demo mesh: ``mesh.examples``' ``bumpy`` surface (a deterministic bumpy ellipsoid).

Provenance: our own — generated on the fly (``mesh.examples.demo_arrays``); no file, no randomness.
``stiefel modes example:NAME`` picks another of ``mesh.examples.EXAMPLES``.
"""

from __future__ import annotations

from mesh.examples import demo_arrays as demo_mesh

__all__ = ["demo_mesh", "DEMO_NAME"]

DEMO_NAME = "demo:bumpy-icosphere"
