"""Built-in methods, one sub-package each (registered in nerf2gs_plugin.registry)."""
