"""Built-in adapters: ``sim`` (simulated robots), ``osc`` (OSC sink), ``console``.

Each is registered in the ``sonibus.adapters`` entry-point group like any
third-party adapter; ``demo.toml`` here is the installation ``sonibus demo`` runs.
"""
