"""Command-line front door: ``stiefel modes | eigs | compare-smoothings`` (issue 6).

The CLI sits on top of the layers (``mesh``, ``objectives``, ``stiefel``) and is
the only place that switches JAX to float64 (``jax_enable_x64``, in ``main``).
Modules: ``cli.main`` (argument parsing, subcommands), ``cli.demo_mesh`` (the
built-in demo surface), ``cli.outputs`` (npz / PLY / JSON writers, μ parsing,
provenance), ``cli.render`` (PNG contact sheet of per-vertex fields).
"""

__all__: list[str] = []
