"""The viser server: panels, frustums, per-client renderers, and the live training hook.

``Viewer`` works on any ``Model`` (built-in or plugin) through ``render_camera`` only. With
``threaded=False`` (the live training view) nothing renders behind the trainer's back: the
trainer's step hook calls :meth:`Viewer.pump`, which renders due frames between steps.
"""

from __future__ import annotations

import math
import queue
import socket
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np
import torch

from nerf2gs_plugin.cameras import Cameras
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.utils.image_metrics import psnr_from_mse
from nerf2gs_plugin.viewer.camera import cameras_to_viser
from nerf2gs_plugin.viewer.render_loop import ClientRenderer, FrameInfo
from nerf2gs_plugin.viewer.resolution import AdaptiveResolution
from nerf2gs_plugin.viewer.scene import (
    EVAL_COLORS, EXTRA_VIEW_COLOR, INPUT_VIEW_COLOR, OTHER_EVAL_COLOR, ExtraViews, available_modes, colorize,
    find_extra_views, frustum_scale, thumbnail,
)


@dataclass
class ViewerConfig:
    host: str = "127.0.0.1"
    """Interface to listen on (0.0.0.0 to serve other machines)."""
    port: int = 7007
    max_side: int = 640
    """Longest side of a full-resolution frame."""
    target_fps: float = 10.0
    """Frame budget while the camera moves (resolution adapts to it)."""
    rest_delay: float = 0.25
    """Seconds without camera motion before refining to full resolution."""
    jpeg_quality: int = 85
    thumbnail_side: int = 96
    max_train_frustums: int = 400
    """Show at most this many training frustums (evenly subsampled)."""


def check_port_free(host: str, port: int) -> None:
    """One-line error when the port is taken (viser itself would silently move to another)."""
    if not 0 < port < 65536:
        raise ConfigError(f"--port {port} is not a TCP port (1-65535)")
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError as e:
            raise ConfigError(f"port {port} on {host} is in use or unavailable ({e.strerror}); pick another with --port") from None


class Viewer:
    """A viser server showing one model, its training/additional/eval cameras and stats."""

    def __init__(self, model: torch.nn.Module, datamanager: Any, *, method_name: str, step: int,
                 config: Optional[ViewerConfig] = None, extra_views: Optional[ExtraViews] = None, threaded: bool = True) -> None:
        import viser

        self.config = config or ViewerConfig()
        self.model = model
        self.datamanager = datamanager
        self.method_name = method_name
        self.step = step
        self.threaded = threaded
        self.mode = "rgb"
        self._render_lock = threading.Lock()
        self._renderers: dict[int, ClientRenderer] = {}
        self._clients_lock = threading.Lock()
        self._tasks: "queue.Queue[Callable[[], None]]" = queue.Queue()
        self._side_by_side: dict[int, Any] = {}
        cfg = self.config
        if cfg.max_side < 16 or cfg.target_fps <= 0:
            raise ConfigError(f"viewer needs max_side >= 16 and target_fps > 0 (got {cfg.max_side}, {cfg.target_fps})")
        check_port_free(cfg.host, cfg.port)
        self.server = viser.ViserServer(host=cfg.host, port=cfg.port, label=f"nerf2gs · {method_name}", verbose=False)
        if self.server.get_port() != cfg.port:
            self.server.stop()
            raise ConfigError(f"port {cfg.port} on {cfg.host} was taken while starting; pick another with --port")
        train_cams = datamanager.train_images.cameras
        self.modes = self._probe_modes(train_cams)
        up = datamanager.train_data.up.float().cpu().numpy()
        self.server.scene.set_up_direction(tuple(float(v) for v in up))
        self._set_initial_camera(train_cams, up)
        self._frustums: dict[str, list[Any]] = {}
        self._eval_targets: list[tuple[str, Cameras, int, Optional[torch.Tensor]]] = []
        self._build_gui()
        self._add_cameras(extra_views)
        self.server.on_client_connect(self._on_connect)
        self.server.on_client_disconnect(self._on_disconnect)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_run(cls, run: Any, config: Optional[ViewerConfig] = None) -> "Viewer":
        """A viewer over a :class:`~nerf2gs_plugin.runs.load.LoadedRun`."""
        cfg = config or ViewerConfig()
        dm = run.pipeline.datamanager
        extra = find_extra_views(run.config, dm.train_data, dm.train_images.cameras, cfg.thumbnail_side)
        return cls(run.model, dm, method_name=run.config.method_name, step=run.step, config=cfg, extra_views=extra)

    def _probe_modes(self, cams: Cameras) -> list[str]:
        probe = cams[0].scaled(min(1.0, 16.0 / float(cams.width[0])))
        return available_modes(self._render_outputs(probe)) or ["rgb"]

    def _set_initial_camera(self, cams: Cameras, up: np.ndarray) -> None:
        centers = cams.centers.detach().cpu().double().numpy()
        extent = float(np.linalg.norm(centers.max(0) - centers.min(0))) or 1.0
        fwd = -cams.camera_to_worlds[0, :, 2].detach().cpu().double().numpy()
        c0 = centers[0]
        ic = self.server.initial_camera
        ic.position = tuple(c0 - fwd * 0.15 * extent + up * 0.1 * extent)
        ic.look_at = tuple(c0 + fwd * 0.3 * extent)
        ic.up = tuple(float(v) for v in up)
        ic.fov = float(cameras_to_viser(cams, 0)[2])

    def stats_markdown(self) -> str:
        size = self.model.size_report() if hasattr(self.model, "size_report") else {}
        lines = [f"**method** {self.method_name}  ", f"**step** {self.step}  "]
        if size:
            kind = size.get("primitive_kind", "primitives")  # None: a NeRF, no primitives to count
            lines += [f"**{kind}** {int(size.get('primitives', 0)):,}  "] if kind else []
            lines += [f"**parameters** {int(size.get('parameters', 0)):,}  ", f"**size** {size.get('megabytes', 0.0):.2f} MB  "]
        lines.append(f"**device** {self.model_device}")
        return "\n".join(lines)

    @property
    def model_device(self) -> torch.device:
        for p in self.model.parameters():
            return p.device
        return torch.device("cpu")

    def _build_gui(self) -> None:
        gui = self.server.gui
        with gui.add_folder("Run"):
            self._stats = gui.add_markdown(self.stats_markdown())
        with gui.add_folder("Render"):
            self._mode_gui = gui.add_dropdown("Mode", tuple(self.modes), initial_value=self.modes[0])
            self._res_gui = gui.add_slider("Max resolution", min=16, max=max(2048, self.config.max_side), step=16,
                                          initial_value=self.config.max_side)
            self._fps_gui = gui.add_slider("Target FPS", min=1, max=60, step=1, initial_value=int(self.config.target_fps))
        self.mode = self.modes[0]

        @self._mode_gui.on_update
        def _(_event) -> None:
            self.mode = self._mode_gui.value
            self.refresh_all()

        @self._res_gui.on_update
        def _(_event) -> None:
            for r in self._renderer_list():
                r.resolution.max_side = int(self._res_gui.value)
            self.refresh_all()

        @self._fps_gui.on_update
        def _(_event) -> None:
            for r in self._renderer_list():
                r.resolution.target_fps = float(self._fps_gui.value)

    def _add_cameras(self, extra: Optional[ExtraViews]) -> None:
        scene, gui, cfg = self.server.scene, self.server.gui, self.config
        dm = self.datamanager
        train = dm.train_images
        scale = frustum_scale(train.cameras.centers)
        step = max(1, math.ceil(len(train) / cfg.max_train_frustums))
        self._frustums["train"] = [
            self._frustum(f"/cameras/input/{i:05d}", train.cameras, i, INPUT_VIEW_COLOR, scale, thumbnail(train.image(i), cfg.thumbnail_side),
                          gt=train.image(i), label=f"input {train.names[i] if i < len(train.names) else i}")
            for i in range(0, len(train), step)
        ]
        if extra is None and getattr(dm, "extra_images", None) is not None:  # live training of an augmented run
            ex = dm.extra_images
            extra = ExtraViews(ex.cameras, [thumbnail(ex.image(j), cfg.thumbnail_side) for j in range(len(ex))], "training data")
        self._frustums["extra"] = [
            self._frustum(f"/cameras/additional/{j:05d}", extra.cameras, j, EXTRA_VIEW_COLOR, scale, extra.thumbnails[j], label=f"additional {j}")
            for j in range(len(extra.cameras))
        ] if extra is not None else []
        self._frustums["eval"] = []
        for split in dm.eval_split_names():
            _, images = dm.eval_split(split)
            color = EVAL_COLORS.get(split, OTHER_EVAL_COLOR)
            for i in range(len(images)):
                img = images.image(i)
                self._frustums["eval"].append(self._frustum(f"/cameras/eval_{split}/{i:05d}", images.cameras, i, color, scale,
                                                            thumbnail(img, cfg.thumbnail_side), gt=img, label=f"{split} {i}"))
                self._eval_targets.append((f"{split} {i}", images.cameras, i, img))
        with gui.add_folder("Cameras"):
            n_extra = len(self._frustums["extra"])
            for key, label in (("train", f"Input views ({len(train)}, red)"), ("extra", f"Additional views ({n_extra}, green)"),
                               ("eval", f"Eval views ({len(self._eval_targets)})")):
                box = gui.add_checkbox(label, initial_value=True, disabled=not self._frustums[key])
                box.on_update(self._visibility_setter(key, box))
        if self._eval_targets:
            with gui.add_folder("Eval cameras"):
                names = tuple(t[0] for t in self._eval_targets)
                self._eval_pick = gui.add_dropdown("Camera", names, initial_value=names[0])
                go = gui.add_button("Go to camera (side-by-side with GT)")

                @go.on_click
                def _(event) -> None:
                    if event.client is not None:
                        label, cams, i, gt = next(t for t in self._eval_targets if t[0] == self._eval_pick.value)
                        self.go_to(event.client, cams, i, gt, label)

    def _visibility_setter(self, key: str, box: Any) -> Callable[[Any], None]:
        def set_visible(_event) -> None:
            for handle in self._frustums[key]:
                handle.visible = bool(box.value)
        return set_visible

    def _frustum(self, name: str, cams: Cameras, i: int, color, scale: float, thumb: Optional[np.ndarray],
                 gt: Optional[torch.Tensor] = None, label: str = "") -> Any:
        wxyz, pos, fov, aspect = cameras_to_viser(cams, i)
        handle = self.server.scene.add_camera_frustum(name, fov=fov, aspect=aspect, scale=scale, color=color, image=thumb,
                                                      wxyz=wxyz, position=pos, thickness=1.5,
                                                      thickness_units="screen")

        @handle.on_click
        def _(event) -> None:
            self.go_to(event.client, cams, i, gt, label)

        return handle

    # ------------------------------------------------------------------ rendering
    def _render_outputs(self, camera: Cameras) -> dict[str, torch.Tensor]:
        with self._render_lock, torch.no_grad():
            was_training = self.model.training
            self.model.eval()
            try:
                return self.model.render_camera(camera.to(self.model_device))
            finally:
                self.model.train(was_training)

    def render_frame(self, camera: Cameras) -> np.ndarray:
        """One viewer frame in the current render mode (``uint8 [H, W, 3]``)."""
        outputs = self._render_outputs(camera)
        mode = self.mode if self.mode in outputs else "rgb"
        return colorize(outputs, mode)

    def go_to(self, client: Any, cams: Cameras, i: int, gt: Optional[torch.Tensor], label: str) -> None:
        """Move a client's camera to a dataset camera; show render | ground truth at its exact intrinsics."""
        wxyz, pos, fov, _ = cameras_to_viser(cams, i)
        with client.atomic():
            client.camera.fov = fov
            client.camera.position = pos
            client.camera.wxyz = wxyz
        if gt is not None:
            self._run_model_task(lambda: self._show_side_by_side(client, cams[i], gt, label))

    def _show_side_by_side(self, client: Any, camera: Cameras, gt: torch.Tensor, label: str) -> None:
        out = self._render_outputs(camera)
        render = out["rgb"][..., :3].detach().float().cpu().clamp(0, 1)
        gt = gt.detach().float().cpu()
        psnr = float(psnr_from_mse(((render - gt) ** 2).mean()))
        sep = torch.ones(render.shape[0], max(2, render.shape[1] // 100), 3)
        pair = (torch.cat([render, sep, gt], dim=1).numpy() * 255 + 0.5).astype(np.uint8)
        text = f"**{label}**: render | ground truth, PSNR {psnr:.2f} dB"
        handles = self._side_by_side.get(client.client_id)
        if handles is None:
            with client.gui.add_folder("Side by side", order=1000):
                handles = (client.gui.add_markdown(text), client.gui.add_image(pair, format="png"))
            self._side_by_side[client.client_id] = handles
        else:
            handles[0].content = text
            handles[1].image = pair
        self.last_side_by_side = {"label": label, "psnr": psnr, "shape": pair.shape}

    def _run_model_task(self, fn: Callable[[], None]) -> None:
        if self.threaded:
            fn()
        else:
            self._tasks.put(fn)

    # ------------------------------------------------------------------ clients
    def _on_connect(self, client: Any) -> None:
        fps = client.gui.add_markdown("**FPS** waiting for the first frame", order=-1000)

        def on_frame(renderer: ClientRenderer, info: FrameInfo) -> None:
            state = "moving" if info.moving else ("full" if info.scale >= 1.0 else "refining")
            fps.content = f"**{1.0 / max(info.seconds, 1e-6):.1f} FPS** · {info.width}x{info.height} · {state}"

        res = AdaptiveResolution(max_side=int(self._res_gui.value), target_fps=float(self._fps_gui.value))
        renderer = ClientRenderer(client, self.render_frame, res, rest_delay=self.config.rest_delay,
                                  jpeg_quality=self.config.jpeg_quality, on_frame=on_frame, threaded=self.threaded)
        with self._clients_lock:
            self._renderers[client.client_id] = renderer
        client.camera.on_update(lambda _cam: renderer.camera_moved())
        renderer.camera_moved()

    def _on_disconnect(self, client: Any) -> None:
        with self._clients_lock:
            renderer = self._renderers.pop(client.client_id, None)
        self._side_by_side.pop(client.client_id, None)
        if renderer is not None:
            renderer.stop()

    def _renderer_list(self) -> list[ClientRenderer]:
        with self._clients_lock:
            return list(self._renderers.values())

    @property
    def frames_rendered(self) -> int:
        """Frames pushed to all clients so far (clients that left included only while connected)."""
        return sum(r.frames for r in self._renderer_list())

    @property
    def renderers(self) -> list[ClientRenderer]:
        return self._renderer_list()

    @property
    def url(self) -> str:
        host = "localhost" if self.config.host in ("0.0.0.0", "") else self.config.host
        return f"http://{host}:{self.server.get_port()}"

    def set_mode(self, mode: str) -> None:
        """Switch the render mode for every client (what the Mode dropdown does)."""
        if mode not in self.modes:
            raise ConfigError(f"render mode '{mode}' is not one of {', '.join(self.modes)}")
        self._mode_gui.value = mode
        self.mode = mode
        self.refresh_all()

    def refresh_all(self) -> None:
        for r in self._renderer_list():
            r.refresh()

    def wait_for_frames(self, count: int, timeout: float, full: bool = False) -> bool:
        """Block until ``count`` frames were rendered (the last one at full resolution if ``full``)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            rs = self._renderer_list()
            if sum(r.frames for r in rs) >= count and (not full or any(r.last and r.last.scale >= 1.0 and not r.last.moving for r in rs)):
                return True
            time.sleep(0.05)
        return False

    # ------------------------------------------------------------------ live training
    def update_model(self, step: int) -> None:
        """The trainer moved on: new stats, and every client re-renders."""
        self.step = step
        self._stats.content = self.stats_markdown()
        self.refresh_all()

    def pump(self) -> int:
        """Render what is due for every client now (``threaded=False``); returns frames rendered."""
        n = 0
        while not self._tasks.empty():
            self._tasks.get_nowait()()
        for r in self._renderer_list():
            n += int(r.pump())
        return n

    def stop(self) -> None:
        for r in self._renderer_list():
            r.stop()
        self.server.stop()


def open_viewer(path: Path, config: Optional[ViewerConfig] = None, device: str = "auto", data: Optional[Path] = None) -> Viewer:
    """Load a run directory or ``.ckpt`` of any registered method and serve it."""
    from nerf2gs_plugin.runs.load import load_run
    from nerf2gs_plugin.engine.trainer import pick_device

    cfg = config or ViewerConfig()
    check_port_free(cfg.host, cfg.port)  # fail before the (slow) load
    run = load_run(Path(path), device=pick_device(device), data=data)
    return Viewer.from_run(run, cfg)


def attach_training_viewer(trainer: Any, config: Optional[ViewerConfig] = None, every_n_steps: int = 10) -> Viewer:
    """Serve the model being trained; frames render between training steps (never during one)."""
    viewer = Viewer(trainer.pipeline.model, trainer.pipeline.datamanager, method_name=trainer.config.method_name,
                    step=trainer.step, config=config, threaded=False)

    def hook(step: int) -> None:
        if (step + 1) % every_n_steps == 0:
            viewer.update_model(step)
        viewer.pump()

    trainer.step_hooks.append(hook)
    trainer.viewer = viewer
    print(f"viewer: {viewer.url}")
    return viewer
