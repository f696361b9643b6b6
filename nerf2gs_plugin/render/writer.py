"""Frames to an MP4 (OpenCV, mp4v) or to numbered PNGs. Written under a temporary name beside the
target and renamed into place when the last frame is in: an interrupted render leaves whatever was
there before untouched."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Literal, Optional

import numpy as np

from nerf2gs_plugin.errors import ConfigError

OutputFormat = Literal["video", "images"]


class FrameWriter:
    """``write(rgb uint8 [H, W, 3])`` per frame, then ``close()`` (or use as a context manager:
    an exception discards the temporary output)."""

    def __init__(self, path: Path, output_format: OutputFormat = "video", fps: float = 10.0) -> None:
        if output_format not in ("video", "images"):
            raise ConfigError(f"--output-format {output_format}: expected video or images")
        self.path, self.format, self.fps = Path(path), output_format, float(fps)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        suffix = ".mp4" if output_format == "video" else ""
        self.tmp = self.path.with_name(f".{self.path.name}.tmp-{os.getpid()}{suffix}")
        self._video = None
        self._size: Optional[tuple[int, int]] = None
        self.frames = 0
        if output_format == "images":
            self.tmp.mkdir()

    def write(self, frame: np.ndarray) -> None:
        import cv2

        h, w = frame.shape[:2]
        if self.format == "images":
            cv2.imwrite(str(self.tmp / f"{self.frames:05d}.png"), frame[..., ::-1])
        else:
            if self._video is None:
                self._size = (w, h)
                self._video = cv2.VideoWriter(str(self.tmp), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, (w, h))
                if not self._video.isOpened():
                    raise ConfigError("OpenCV cannot write an mp4v video here (try --output-format images)", self.path)
            if (w, h) != self._size:  # a video has one frame size: pad or crop to the first
                canvas = np.zeros((self._size[1], self._size[0], 3), np.uint8)
                canvas[: min(h, self._size[1]), : min(w, self._size[0])] = frame[: self._size[1], : self._size[0]]
                frame = canvas
            self._video.write(np.ascontiguousarray(frame[..., ::-1]))
        self.frames += 1

    def close(self) -> Path:
        """Finish and move the output into place; returns its path."""
        if self._video is not None:
            self._video.release()
            self._video = None
        old = None
        if self.format == "images" and self.path.is_dir():  # a folder cannot be renamed over: move the old one aside first
            old = self.path.with_name(f".{self.path.name}.old-{os.getpid()}")
            os.replace(self.path, old)
        os.replace(self.tmp, self.path)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        return self.path

    def discard(self) -> None:
        if self._video is not None:
            self._video.release()
            self._video = None
        if self.tmp.is_dir():
            shutil.rmtree(self.tmp, ignore_errors=True)
        else:
            self.tmp.unlink(missing_ok=True)

    def __enter__(self) -> "FrameWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.discard()
