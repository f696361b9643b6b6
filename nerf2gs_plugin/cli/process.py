"""``ns2gs-data process video FILE --out DATA`` and ``ns2gs-data process images DIR --out DATA``."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import tyro

from nerf2gs_plugin.data.process.pipeline import ProcessOptions


@dataclass
class ProcessVideo(ProcessOptions):
    """A video (e.g. a dashcam drive) -> frames (sharpest per window, blurry ones dropped) -> pycolmap
    SfM (sequential matching) -> undistorted PINHOLE dataset with metric scale from the ground plane."""

    video: tyro.conf.Positional[Path] = Path("video.mp4")
    """The video file (anything OpenCV decodes: mp4, avi, mov, ...)."""
    num_frames: Optional[int] = 150
    """Frames to keep, evenly spread over the video (ignored when --fps is set)."""
    fps: Optional[float] = None
    """Frames per second of video to keep (instead of --num-frames)."""
    blur_ratio: float = 0.5
    """Drop a frame whose sharpness (variance of Laplacian) is below this x its neighbours' median (0: keep all)."""

    def check_flags(self) -> None:
        """--fps and --num-frames, before anything is read or written."""
        import math

        from nerf2gs_plugin.data.process.frames import MIN_FRAMES
        from nerf2gs_plugin.errors import ConfigError

        if self.fps is not None and not (math.isfinite(self.fps) and self.fps > 0):
            raise ConfigError(f"--fps must be a positive number of frames per second of video, got {self.fps}", "--fps")
        if self.fps is None and self.num_frames is not None and self.num_frames < MIN_FRAMES:
            raise ConfigError(f"--num-frames must be at least {MIN_FRAMES}, got {self.num_frames}", "--num-frames")

    def main(self) -> None:
        from nerf2gs_plugin.data.process.frames import extract_video_frames, video_size_hint
        from nerf2gs_plugin.data.process.pipeline import run_process

        self.check_flags()
        n = None if self.fps else self.num_frames

        def frames(frame_dir: Path, progress):
            return extract_video_frames(self.video, frame_dir, self.fps, n, self.blur_ratio, self.max_size, progress=progress,
                                        crop=self.crop_factor)

        hint = video_size_hint(self.video, self.fps, n, self.max_size)
        for line in run_process(frames, self, is_video=True, size_hint=hint).lines():
            print(line)


@dataclass
class ProcessImages(ProcessOptions):
    """A folder of JPEG/PNG photos (capture order = natural name order) -> pycolmap SfM (exhaustive
    matching up to --exhaustive-max photos, sequential beyond; EXIF focal used when present) ->
    undistorted PINHOLE dataset with metric scale from the ground plane."""

    images: tyro.conf.Positional[Path] = Path("images")
    """Folder of photos."""

    def main(self) -> None:
        from nerf2gs_plugin.data.process.frames import collect_images, images_size_hint, list_images
        from nerf2gs_plugin.data.process.pipeline import exif_focal_for, run_process

        def frames(frame_dir: Path, progress):
            return collect_images(self.images, frame_dir, self.max_size, progress, crop=self.crop_factor)

        sources = list_images(self.images)
        report = run_process(frames, self, is_video=False, focal_px_fn=lambda d, names: exif_focal_for(sources, d, names, self.kept_width),
                             size_hint=images_size_hint(sources, self.max_size))
        for line in report.lines():
            print(line)
