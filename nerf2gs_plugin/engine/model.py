"""The Model contract every method implements (built-in or third-party plugin)."""

from __future__ import annotations

from abc import ABCMeta, abstractmethod
from dataclasses import dataclass, field
from typing import Any, Callable, Optional, Union

import torch
from torch import Tensor, nn

from nerf2gs_plugin.cameras import Cameras, RayBundle
from nerf2gs_plugin.data.dataparser_outputs import DataparserOutputs
from nerf2gs_plugin.engine.callbacks import TrainingCallback, TrainingCallbackAttributes
from nerf2gs_plugin.utils.config import InstantiateConfig
from nerf2gs_plugin.utils.image_metrics import psnr_from_mse


@dataclass
class ModelConfig(InstantiateConfig):
    _target: type = field(default_factory=lambda: Model)


class Model(nn.Module, metaclass=ABCMeta):
    """A trainable scene representation (an abstract base class: a method that leaves a contract
    method out fails when built, naming it).

    Ray methods (NeRFs) get a :class:`RayBundle` in :meth:`get_outputs`; image methods (splatting)
    get a one-camera :class:`Cameras`. Either way, :meth:`render_camera` renders one whole image and
    is what eval, the viewer and the augmentation of another method call.

    Batches (from the DataManager):
      * rays:   ``{"rgb": [R,3], "weight": [R,1], "image_idx": [R], "<kind>_mask": [R,1] bool}``
      * images: ``{"image": [H,W,3], "weight": float tensor [], "image_idx": int, "<kind>_mask": [H,W,1] bool}``
        and, for a reference's render with ``--augment.confidence``, ``"confidence": [H,W,1]`` float in [0, 1]
        (a per-pixel loss weight; for rays it is folded into ``weight``)
      with ``<kind>`` in sky / ground / transient when the dataset has those masks.
    """

    config: ModelConfig
    primitive_kind: Union[str, None] = "primitives"
    """What :meth:`num_primitives` counts, as shown to people ("Gaussians", "anchors"); None for
    a model without primitives (a NeRF: its size is parameters and MB, not hash-table entries)."""

    depth_along: str = "z"
    """What ``render_camera``'s ``depth`` measures: "z" (camera-space z, splatting) or "ray" (distance along
    the unit ray, NeRFs); the augmentation lifts a reference's pixels to 3D with it."""

    def __init__(self, config: ModelConfig, train_data: DataparserOutputs, **kwargs: Any) -> None:
        super().__init__()
        self.config = config
        self.scene_box = train_data.scene_box.clone()
        self.num_train_images = len(train_data)
        self._train_cameras: Optional[Callable[[], Cameras]] = None
        """Every training view (real and extra) once training named them (:meth:`name_training_views`)."""
        self._train_batch: Optional[Callable[[int], dict[str, Any]]] = None
        """Training view ``i`` of those as a whole-image batch (image and masks), once training named them."""
        self.populate_modules(train_data)

    @property
    def device(self) -> torch.device:
        for p in self.parameters():
            return p.device
        for b in self.buffers():
            return b.device
        return torch.device("cpu")

    def populate_modules(self, train_data: DataparserOutputs) -> None:
        """Create fields, parameters and losses (nerfstudio's hook of the same name)."""

    @abstractmethod
    def get_param_groups(self) -> dict[str, list[nn.Parameter]]:
        """Parameter groups by name; the method config has an optimizer for each name."""

    @abstractmethod
    def get_outputs(self, inputs: Union[RayBundle, Cameras]) -> dict[str, Tensor]: ...

    def get_train_outputs(self, inputs: Union[RayBundle, Cameras], batch: dict[str, Any]) -> dict[str, Tensor]:
        """:meth:`get_outputs` of a training batch: a model may leave out what no loss of ``batch`` reads."""
        return self.get_outputs(inputs)

    @abstractmethod
    def get_loss_dict(self, outputs: dict[str, Tensor], batch: dict[str, Any], metrics_dict: dict[str, Tensor]) -> dict[str, Tensor]:
        """Scalar losses; the trainer minimises their sum."""

    def get_metrics_dict(self, outputs: dict[str, Tensor], batch: dict[str, Any]) -> dict[str, Tensor]:
        pred = outputs["rgb"]
        gt = batch["rgb"] if "rgb" in batch else batch["image"]
        return {"psnr": psnr_from_mse(((pred.detach() - gt) ** 2).mean())}

    def get_training_callbacks(self, attrs: TrainingCallbackAttributes) -> list[TrainingCallback]:
        return []

    def name_training_views(self, attrs: TrainingCallbackAttributes) -> None:
        """From now on read the training views (real and extra) from the pipeline's data manager: for what
        a model decides from its views (a densification budget, a prune). Called by get_training_callbacks."""
        if getattr(attrs.pipeline, "datamanager", None) is not None:
            self._train_cameras = lambda: attrs.pipeline.datamanager.all_train_cameras
            self._train_batch = lambda i: attrs.pipeline.datamanager.train_batch(i)

    def add_extra_views(self, count: int) -> None:
        """The training views gain ``count`` additional views (``image_idx`` from ``num_train_images`` on),
        before the optimizers are built: for a model that learns something per view (none by default)."""

    def training_pixels(self) -> Optional[int]:
        """Pixels in every training view (real and extra), or None before training named them."""
        return None if self._train_cameras is None else self._train_cameras().pixel_count()

    @abstractmethod
    @torch.no_grad()
    def render_camera(self, camera: Cameras) -> dict[str, Tensor]:
        """One camera (``len(camera) == 1``) in, ``{"rgb": [H,W,3], "depth": [H,W,1],
        "accumulation": [H,W,1], ...}`` out, on the model's device."""

    def refined_train_cameras(self, cameras: Cameras) -> Optional[Cameras]:
        """The training cameras (``cameras``, in training-image order) where the model learned their
        images were taken (a camera optimizer's refined poses), or None when the dataset's poses are
        the model's (the default). The augmentation renders the input views from these."""
        return None

    def add_initial_points(self, xyz: Tensor, rgb: Tensor) -> int:
        """Start also from these points ``[P, 3]`` (normalised world) with colours ``[P, 3]`` (0-1), before
        training (:meth:`DataManager.initial_points`); returns how many primitives were added. A model that
        does not start from points ignores them (the default)."""
        return 0

    def training_state(self) -> dict[str, Tensor]:
        """What a resumed run needs besides the parameters and the optimizers' moments (a densification
        strategy's accumulated statistics); written into every checkpoint. Nothing by default."""
        return {}

    def load_training_state(self, state: dict[str, Tensor]) -> None:
        """Restore :meth:`training_state` on resume (empty: a checkpoint without it)."""

    def num_primitives(self) -> int:
        """Gaussians, anchors or surfels; grid cells or hash entries for fields."""
        return 0

    def size_report(self) -> dict[str, float]:
        """Primitives, parameters and megabytes of state: printed beside every quality figure."""
        n_params = sum(p.numel() for p in self.parameters())
        n_bytes = sum(t.numel() * t.element_size() for t in self.state_dict().values())
        return {"primitives": int(self.num_primitives()), "primitive_kind": self.primitive_kind,
                "parameters": int(n_params), "megabytes": n_bytes / 2**20}

    def load_model_state(self, state: dict[str, Tensor]) -> None:
        """Load a state dict; methods whose parameter shapes change (densification) override this."""
        self.load_state_dict(state)
