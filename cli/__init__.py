"""Command-line front door: ``stiefel modes | eigs | compare-smoothings`` (issue 6).

The CLI sits on top of the layers (``mesh``, ``objectives``, ``stiefel``) and is
the only place that switches JAX to float64 (``jax_enable_x64``, in ``main``).
Modules: ``cli.main`` (argument parsing, signals, exit codes), ``cli.commands``
(the three subcommands), ``cli.run_dir`` (atomic output directories: staging,
fsync, commit with ``summary.json`` last, lock), ``cli.demo_mesh`` (the built-in
demo surface), ``cli.outputs`` (npz / PLY writers, μ parsing, provenance),
``cli.render`` and ``cli.render_views`` (PNG contact sheets: principal-axes orientation, views, z-buffer
rasteriser), ``cli.viewer`` (self-contained HTML viewer, ``stiefel view``), ``cli.options`` (the options
and their API names), ``cli.compare`` (``compare-smoothings``).
"""

__all__: list[str] = []
