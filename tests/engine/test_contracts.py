"""Model and DataManager are abstract base classes: a method that leaves a contract method out fails
when it is built, naming the method, instead of deep inside training."""

from __future__ import annotations

import inspect

import pytest

from nerf2gs_plugin.datamanagers.base import DataManager
from nerf2gs_plugin.engine.model import Model


def test_the_contract_methods_are_abstract():
    assert inspect.isabstract(Model) and inspect.isabstract(DataManager)
    assert {"get_param_groups", "get_outputs", "get_loss_dict", "render_camera"} <= Model.__abstractmethods__
    assert {"next_train"} <= DataManager.__abstractmethods__


def test_a_model_without_render_camera_cannot_be_built():
    class Partial(Model):
        def get_param_groups(self):
            return {}

        def get_outputs(self, inputs):
            return {}

        def get_loss_dict(self, outputs, batch, metrics_dict):
            return {}

    with pytest.raises(TypeError, match="render_camera"):
        Partial(None, None)


def test_the_example_plugin_method_implements_the_contract():
    ns2gs_example_method = pytest.importorskip("ns2gs_example_method")
    models = [v for v in vars(ns2gs_example_method).values() if inspect.isclass(v) and issubclass(v, Model) and v is not Model]
    assert models and not any(inspect.isabstract(m) for m in models)


def test_what_reads_a_run_config_does_not_import_the_training_loop():
    """The registry and the reference loader read TrainerConfig from its own module: importing them
    loads no Trainer (the loop imports them; the other way round was an import circle). Plugins that
    import TrainerConfig from engine.trainer get the same class."""
    import subprocess
    import sys

    code = ("import sys, nerf2gs_plugin.runs.load, nerf2gs_plugin.registry, nerf2gs_plugin.engine.trainer_config; "
            "print('nerf2gs_plugin.engine.trainer' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "False"
    from nerf2gs_plugin.engine.trainer import TrainerConfig as from_loop
    from nerf2gs_plugin.engine.trainer_config import TrainerConfig

    assert from_loop is TrainerConfig
