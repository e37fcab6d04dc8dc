"""Compilation runtime: how the solvers' programs are built, stored and shared.

* ``compilation`` — ahead-of-time compilation (``compile_aot``), ``run_compiled``, host transfers and the
  ``is_traced`` test every solver uses to tell a traced call from a concrete one.
* ``program_cache`` — ``minimize``'s traced programs stored with ``jax.export`` beside JAX's persistent
  compilation cache, so a new process neither traces nor compiles them.
* ``buckets`` — the size grid on which ``objectives.BlockCMM`` pads problems so that similar sizes share
  one program.

Nothing here imports the rest of ``stiefel``.
"""
