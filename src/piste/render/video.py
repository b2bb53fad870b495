"""MP4 output: H.264 through imageio-ffmpeg (ffmpeg ships inside the wheel), written atomically."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from types import TracebackType

import numpy as np

from piste.errors import RenderError
from piste.extras import require

__all__ = ["VideoWriter"]


class VideoWriter:
    """Append ``(H, W, 3) uint8`` frames; :meth:`close` moves the finished MP4 into place.

    The file is written under a temporary name in the target folder and renamed on success, so a
    reader never sees a half-written video; :meth:`abort` (or an exception inside ``with``) removes it.
    """

    def __init__(self, path: str | os.PathLike[str], fps: int = 30, quality: float = 7.0) -> None:
        imageio = require("imageio.v2", "MP4 output")

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        import tempfile  # (stdlib: imported when a video is written, not by every render)

        fd, tmp = tempfile.mkstemp(prefix=f".{self.path.stem}.", suffix=".mp4", dir=self.path.parent)
        os.close(fd)
        self._tmp = Path(tmp)
        self.frames = 0
        self.size: tuple[int, ...] | None = None
        try:
            self._writer = imageio.get_writer(
                self._tmp, format="FFMPEG", mode="I", fps=fps, codec="libx264", quality=quality,
                pixelformat="yuv420p", macro_block_size=2, ffmpeg_log_level="error",
            )
        except Exception as exc:
            self._tmp.unlink(missing_ok=True)
            raise RenderError(f"{self.path}: cannot start the video encoder: {exc}") from None

    def append(self, image: np.ndarray) -> None:
        img = np.asarray(image)
        if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (3, 4):
            raise RenderError(f"{self.path}: frames must be (H, W, 3) uint8, got {img.shape} {img.dtype}")
        if self.size is None:
            self.size = img.shape[:2]
            if self.size[0] % 2 or self.size[1] % 2:
                raise RenderError(f"{self.path}: H.264 needs an even width and height, got {img.shape[1]}x{img.shape[0]}")
        elif img.shape[:2] != self.size:
            raise RenderError(f"{self.path}: frame {self.frames} is {img.shape[:2]}, earlier frames {self.size}")
        self._writer.append_data(np.ascontiguousarray(img[..., :3]))
        self.frames += 1

    def close(self) -> Path:
        self._writer.close()
        if self.frames == 0:
            self._tmp.unlink(missing_ok=True)
            raise RenderError(f"{self.path}: no frames were written")
        self._tmp.chmod(0o644)
        os.replace(self._tmp, self.path)
        return self.path

    def abort(self) -> None:
        with contextlib.suppress(Exception):
            self._writer.close()
        self._tmp.unlink(missing_ok=True)

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
