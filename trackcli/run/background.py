"""Work moved off the tracking thread: decoding ahead, and writing the recording.

Both keep the order of the frames and bounded queues (memory does not grow with the clip),
and hand any error back to the caller.
"""

from __future__ import annotations

import collections
import queue
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable, Iterable, Iterator


class DecodeAhead:
    """Decode frames ahead in a background thread; keep the current frame and the timings.

    Decoding (OpenCV releases the GIL while it decodes) overlaps with tracking; at most
    ``depth`` decoded frames wait in the queue, so memory does not grow with the clip.
    ``prepare``, when given, turns each decoded frame into what the consumer gets, in the
    same thread (the tracker's whole-frame images, :meth:`trackcli.trackers.base.Tracker.prepare`).
    ``decode_seconds`` is the decoding time, ``prepare_seconds`` the time in ``prepare``,
    ``wait_seconds`` the time the consumer spent waiting for a frame.  ``current`` is the last
    frame handed out, :meth:`frame_at` one of the last few by its index.  :meth:`close` stops
    the thread (call it before the video closes).
    """

    #: the frames handed out that :meth:`frame_at` still finds
    RECENT = 4

    _END = object()

    def __init__(self, frames: Iterable[Any], depth: int = 4, prepare: Callable[[Any], Any] | None = None):
        self._it = iter(frames)
        self._prepare = prepare
        self.prepare_seconds = 0.0
        self.decode_seconds = 0.0
        self.wait_seconds = 0.0
        self.current: Any = None
        self._recent: collections.deque = collections.deque(maxlen=self.RECENT)
        self._queue: queue.Queue = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._done = False
        self._thread = threading.Thread(target=self._decode, name="trackcli-decode", daemon=True)
        self._thread.start()

    def _put(self, item: Any) -> bool:
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _decode(self) -> None:
        try:
            while not self._stop.is_set():
                t0 = time.perf_counter()
                try:
                    frame = next(self._it)
                except StopIteration:
                    break
                finally:
                    self.decode_seconds += time.perf_counter() - t0
                if self._prepare is not None:
                    t0 = time.perf_counter()
                    frame = self._prepare(frame)
                    self.prepare_seconds += time.perf_counter() - t0
                if not self._put(frame):
                    return
            self._put(self._END)
        except BaseException as exc:  # handed to the consumer, raised there
            self._put(exc)

    def __iter__(self) -> Iterator[Any]:
        return self

    def __next__(self) -> Any:
        if self._done:
            raise StopIteration
        t0 = time.perf_counter()
        item = self._queue.get()
        self.wait_seconds += time.perf_counter() - t0
        if item is self._END:
            self._done = True
            raise StopIteration
        if isinstance(item, BaseException):
            self._done = True
            raise item
        self.current = item
        self._recent.append(item)
        return item

    def frame_at(self, index: int) -> Any:
        """The frame of ``index`` among the last :data:`RECENT` handed out (the newest of that
        index), else :attr:`current`."""
        for item in reversed(self._recent):
            if getattr(item, "index", None) == index:
                return item
        return self.current

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


class BackgroundRecorder:
    """Log each frame's result to the recording in a background thread, in order.

    ``log(rec, log_frame, image, result)`` does the logging of one frame.

    JPEG encoding and Rerun's logging overlap with the tracking of the next frames; at most
    ``depth`` frames wait, and an error in the recorder is raised in the caller at the next
    frame or at :meth:`finish`.
    """

    def __init__(self, rec: Any, log_frame: Any, log: Callable[[Any, Any, Any, Any], None], depth: int = 8):
        self._rec, self._log_frame, self._log, self._depth = rec, log_frame, log, depth
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="trackcli-record")
        self._pending: collections.deque = collections.deque()
        self._count = 0
        self.seconds = 0.0

    #: frames between two flushes of the recording to its file, which keep Rerun's buffers
    #: from growing with the clip
    FLUSH_EVERY = 200
    #: every this many frames, the images and overlays held (as columns,
    #: :meth:`trackcli.io.recording.Recording.batch_overlays`) are sent, entity by entity,
    #: once they hold ``SEND_BYTES`` of data or ``HOLD_FRAMES`` frames: a 320 x 240 clip's
    #: images and particle contours every 25 frames, its centroid every 250.  Each send is a
    #: chunk of the recording, and the file writer keeps about a kilobyte of every chunk in
    #: memory until the recording is closed; sending the light entities as often as the
    #: images made the process grow by 0.7-1.0 kB per frame, this by 0.35-0.5.
    BATCH_FRAMES = 25
    SEND_BYTES = 256 * 1024
    HOLD_FRAMES = 250

    def _record(self, image: Any, r: Any) -> None:
        t0 = time.perf_counter()
        if self._count == 0:
            self._rec.batch_overlays()
        self._log(self._rec, self._log_frame, image, r)
        self._count += 1
        if self._count % self.BATCH_FRAMES == 0:
            self._rec.flush_overlays(min_bytes=self.SEND_BYTES, max_rows=self.HOLD_FRAMES)
        if self._count % self.FLUSH_EVERY == 0:
            self._rec.stream.flush()
        self.seconds += time.perf_counter() - t0

    def submit(self, image: Any, r: Any) -> None:
        self._pending.append(self._pool.submit(self._record, image, r))
        self._drain()

    def _drain(self) -> None:
        """Collect the finished work (raising its error), and wait while more than ``depth`` wait."""
        while self._pending and (self._pending[0].done() or len(self._pending) > self._depth):
            self._pending.popleft().result()

    def call(self, fn: Callable[..., None], *args: Any) -> None:
        """Run ``fn(*args)`` in the recorder's thread, after the frames submitted so far."""
        self._pending.append(self._pool.submit(fn, *args))
        self._drain()

    def finish(self) -> None:
        """Wait for every frame (and send the frames still held in a batch); raise the first error."""
        try:
            self._pending.append(self._pool.submit(self._rec.flush_overlays, last=True))
            while self._pending:
                self._pending.popleft().result()
        finally:
            self.close()

    def close(self) -> None:
        for f in self._pending:
            f.cancel()
        self._pool.shutdown(wait=True)
        self._pending.clear()
