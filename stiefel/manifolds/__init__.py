"""The manifolds and their geometry (docs/maths.md §1–3).

* ``manifold`` — ``GeneralizedStiefel``: ``{X : XᵀMX = I}``, projections, metrics, retractions' front end.
* ``retractions`` — the retractions (polar, QR, Cayley, …) and their inverses.
* ``geodesics`` — exponential map, logarithm and distance.
* ``grassmann`` — ``Grassmann`` (the quotient by O(k)), ``sphere`` and ``stiefel``.
* ``product`` — ``Product`` of manifolds; points are tuples of arrays.
* ``tangent_algebra`` — inner products and updates of tangent vectors that are arrays or tuples.
* ``signs`` — ``canonical_signs``: the sign convention of every returned basis.
"""
