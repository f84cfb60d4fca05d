"""Training batches from an endless, deterministic stream of clips made in worker processes.

:class:`ClipSource` makes clips ``0, 1, 2, ...`` of a recipe in order, on
``workers`` processes (spawned, numpy only), at most ``prefetch`` ahead, so the
trainer never waits while the workers keep up; ``workers=0`` makes them in
this process (tests, debugging).

:class:`ClipPool` holds ``capacity`` clips. Before step ``s`` of a run, clip
``capacity + s // refresh - 1`` replaces the oldest every ``refresh`` steps:
which clips a step can draw from depends only on the step, never on how fast
the workers were, so a run is a pure function of its seed and resumes
exactly (the pool is re-made from the step). Each sample is a key moment drawn
anywhere in a clip (its span padded at the stream's ends by repeating the
first or last readout, exactly as inference does: :func:`tespike.recon.learning.span.key_span`, and marked as
padding by :func:`tespike.recon.learning.span.span_inside`),
a random crop and random flips.
"""

from __future__ import annotations

import collections
import contextlib
import multiprocessing
import os
import signal
import threading
import time
import weakref

import numpy as np
import torch

from tespike.golden.config import SensorConfig

from ..calibration import correct_input
from ..decoding import decode_light
from ..learning.span import key_span, span_inside
from .clips import Clip, EngineRecipe, make_clip


def _make(args) -> Clip:
    recipe, config, index = args
    return make_clip(recipe, config, index)


#: Seconds between a worker's checks that the trainer that started it is alive.
PARENT_POLL = 0.2


def _worker_init(parent: int) -> None:
    """A worker runs at lower priority and ends when the trainer is gone, however it ended (even
    killed, with no chance to end its workers), without a word once it is gone."""
    import sys
    for number in _HELD_AT_START:                       # (the trainer answers Ctrl-C and a hang-up: _ctrl_c_held)
        signal.signal(number, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, set(_HELD_AT_START))
    try:
        os.nice(5)              # the trainer keeps priority on a shared machine
    except OSError:
        pass
    sys.stderr = _WhileParent(sys.stderr, parent)
    threading.Thread(target=_exit_without, args=(parent,), daemon=True).start()


class _WhileParent:
    """A worker's stderr that writes only while the trainer that started it lives: a trainer killed
    outright breaks the pipe the worker sends its clip on, and the pool would print that
    ``BrokenPipeError`` to the user's terminal after the kill (nobody is left to read it). Nor
    while a broken pipe is being handled: the dying trainer's pipe closes before its children are
    handed to another parent, so the pool's first line ("Process SpawnPoolWorker-1:") got through.
    A clip's own error still reaches the trainer, which raises it."""

    def __init__(self, stream, parent: int):
        self._stream, self._parent = stream, parent

    def _open(self) -> bool:
        import sys
        return os.getppid() == self._parent and not isinstance(sys.exception(), (BrokenPipeError, EOFError,
                                                                                 ConnectionError))

    def write(self, text: str) -> int:
        return self._stream.write(text) if self._open() else len(text)

    def flush(self) -> None:
        if self._open():
            self._stream.flush()

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _exit_without(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(PARENT_POLL)
    os._exit(0)                 # quietly: nobody is left to take the clip being made


#: The resource tracker's notice of the pool's semaphores, which it removes itself when the trainer
#: is killed (SIGKILL, no chance to close the pool): a line on the user's terminal after the kill.
_TRACKER_NOTICE = "ignore::UserWarning:multiprocessing.resource_tracker"


def _quiet_resource_tracker() -> None:
    """The resource tracker (a process of its own, started with the pool) inherits this interpreter's
    ``-W`` options: it still cleans up after a killed trainer, without a warning on stderr."""
    import sys
    if _TRACKER_NOTICE not in sys.warnoptions:
        sys.warnoptions.append(_TRACKER_NOTICE)


#: What a terminal sends the whole process group, which the trainer answers for its workers (ending
#: them): Ctrl-C and, the terminal closed, SIGHUP (a worker that died of it first was one the pool
#: started again while the trainer was ending it).
_HELD_AT_START = tuple(getattr(signal, name) for name in ("SIGINT", "SIGHUP") if hasattr(signal, name))


@contextlib.contextmanager
def _ctrl_c_held():
    """Ctrl-C held while the workers start, then answered: it reaches a terminal's whole process
    group, and the trainer, not each worker, answers it (ending the workers). SIGINT is blocked in
    this thread, a mask the workers inherit across their exec (each then ignores it and unblocks
    it, :func:`_worker_init`, which discards one already pending), and a SIGINT that comes in the
    meantime (through this thread's mask on unblocking, or through another thread's) is only
    noted; once the start is over it is raised again through the handler that was there before.
    (Ignored instead, it was lost, and the run went on.) Only the main thread can change the
    handlers (elsewhere nothing changes)."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    from multiprocessing import resource_tracker
    # (its start, inside, would unblock SIGINT: it blocks and unblocks). The tracker ignores SIGINT and
    # SIGTERM itself, not SIGHUP: a closed terminal's SIGHUP ended it, and the tracker started again in
    # its place printed a KeyError traceback for each semaphore the first had held. Blocked here, SIGHUP
    # stays blocked in the tracker (it ends when the trainer and its workers are gone) and comes to
    # this process once the mask is restored.
    hangup = {signal.SIGHUP} if hasattr(signal, "SIGHUP") else set()
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, hangup)
    try:
        resource_tracker.ensure_running()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    held = []
    previous = {number: signal.signal(number, lambda number, frame: held.append(number)) for number in _HELD_AT_START}
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, set(_HELD_AT_START))
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)     # (one held here is noted now)
        for number, handler in previous.items():
            signal.signal(number, handler)
    for number in dict.fromkeys(held):
        signal.raise_signal(number)


#: What ends the trainer's own writes through the relay (:func:`_children_stderr_relayed`); one
#: write of it is atomic on a pipe, and the relay takes it out.
_RELAY_MARK = b"\0tespike: relayed up to here\0"


@contextlib.contextmanager
def _children_stderr_relayed():
    """Processes started inside get, as their stderr, a pipe this process relays to its own stderr for
    as long as it lives. A trainer killed outright (``kill -9``) in the instant between starting a
    worker and handing it its start-up data left the worker's start-up traceback ("EOFError: Ran out
    of input", before any code of tespike runs there) on the user's terminal; with the trainer gone
    the pipe has no reader, and such a write goes nowhere. This process's own writes inside go
    through the relay too, and are out before the block ends (in order with what follows). Only the
    main thread changes file descriptor 2 (elsewhere nothing changes)."""
    import sys
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    with contextlib.suppress(OSError, ValueError):
        sys.stderr.flush()
    opened = []
    try:                                   # (no stderr, or no file handle to spare: no relay)
        opened += os.pipe()
        opened += (os.dup(2), os.dup(2))
    except OSError:
        for fd in opened:
            os.close(fd)
        yield
        return
    read, write, terminal, restore = opened       # (terminal: the relay's, closed by it; restore: this thread's)
    marked = threading.Event()

    def relay() -> None:
        held = b""                         # (a part of the mark, until the read that completes it)
        try:
            while chunk := os.read(read, 1 << 16):
                data = held + chunk
                while (at := data.find(_RELAY_MARK)) >= 0:
                    _write_all(terminal, data[:at])
                    data = data[at + len(_RELAY_MARK):]
                    marked.set()
                keep = next((k for k in range(min(len(data), len(_RELAY_MARK) - 1), 0, -1)
                             if data.endswith(_RELAY_MARK[:k])), 0)
                held = data[len(data) - keep:]
                _write_all(terminal, data[:len(data) - keep])
            _write_all(terminal, held)
        except OSError:                    # (the terminal gone: the workers' lines go nowhere)
            pass
        finally:
            os.close(read)
            os.close(terminal)
    try:
        threading.Thread(target=relay, name="tespike-worker-stderr", daemon=True).start()
    except RuntimeError:                   # (no thread to spare: the workers keep this stderr)
        for fd in opened:
            os.close(fd)
        yield
        return
    os.dup2(write, 2)
    os.close(write)
    try:
        yield
    finally:
        with contextlib.suppress(OSError, ValueError):
            sys.stderr.flush()
        with contextlib.suppress(OSError):
            os.write(2, _RELAY_MARK)
            marked.wait(5)                 # (the relay has written everything before the mark)
        os.dup2(restore, 2)                # (the relay's write ends now live in the workers alone)
        os.close(restore)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _end_workers_started(before: set) -> None:
    """The worker processes a pool started before its own start failed (one of its three handler
    threads could not start: out of memory): ended by :func:`_kill_workers`, so that none, still
    reading its start-up data from a trainer that has gone, prints that traceback after the
    trainer's one line. The pool object never reached the caller: its worker-handler thread is
    found among the threads and its workers among the children started since ``before``."""
    from multiprocessing import pool as pools
    def function(target):                      # (the handler is a classmethod: its function)
        return getattr(target, "__func__", target)
    handlers = [thread for thread in threading.enumerate()
                if function(getattr(thread, "_target", None)) is function(pools.Pool._handle_workers)]
    _kill_workers(handlers, [process for process in multiprocessing.active_children() if process not in before])


def _kill_workers(handlers, processes) -> None:
    """End a pool's workers without ``Pool.terminate``: its worker-handler threads ``handlers``
    told to stop first (as ``terminate`` tells them, by their ``_state``; one left running starts
    new workers in place of those killed), then each of ``processes`` killed and reaped, then the
    handlers joined (a handler waits on its workers' ends, so it leaves once they are gone)."""
    from multiprocessing import pool as pools
    for thread in handlers:
        thread._state = pools.TERMINATE
    for process in processes:
        with contextlib.suppress(OSError, ValueError):
            process.kill()
            process.join(5)
    for thread in handlers:
        if thread is not threading.current_thread() and thread.is_alive():
            thread.join(5)


#: The result-handler threads of the clip sources' pools, and why one ended, by thread
#: (:func:`_note_pool_thread_failure`).
_RESULT_HANDLERS: "weakref.WeakSet[threading.Thread]" = weakref.WeakSet()
_POOL_THREAD_FAILURES: "weakref.WeakKeyDictionary[threading.Thread, BaseException]" = weakref.WeakKeyDictionary()

#: Seconds a clip is waited for between checks that the pool can still deliver it.
RESULT_POLL_SECONDS = 1.0


def _note_pool_thread_failure(args, previous=threading.excepthook) -> None:
    """``threading.excepthook``: a clip source's pool result-handler thread that dies (starved of
    memory while a clip's bytes came in, ``ulimit -v``) is noted for the trainer, whose wait then
    raises it (:meth:`ClipSource._wait`) and ends in the command's one line; Python had printed the
    thread's 13-line traceback first. Any other thread's exception is the previous hook's."""
    if args.thread is not None and args.thread in _RESULT_HANDLERS:
        _POOL_THREAD_FAILURES[args.thread] = args.exc_value
        return
    previous(args)


class ClipSource:
    """Clips ``start, start + 1, ...`` in order, made ahead on worker processes."""

    def __init__(self, recipe: EngineRecipe, config: SensorConfig, *, start: int = 0,
                 workers: int = 1, prefetch: int = 8):
        self.recipe, self.config, self.next_index = recipe, config, start
        self.prefetch = max(1, prefetch)
        self.pool = None
        if workers > 0:
            _quiet_resource_tracker()
            before = set(multiprocessing.active_children())
            try:
                with _ctrl_c_held(), _children_stderr_relayed():   # the workers inherit both
                    self.pool = multiprocessing.get_context("spawn").Pool(workers, initializer=_worker_init,
                                                                          initargs=(os.getpid(),))
            except BaseException:
                if self.pool is not None:   # started; a Ctrl-C held during the start came in
                    self.close()
                else:
                    _end_workers_started(before)
                raise
            handler = getattr(self.pool, "_result_handler", None)
            if handler is not None:
                _RESULT_HANDLERS.add(handler)
                if threading.excepthook is not _note_pool_thread_failure:
                    threading.excepthook = _note_pool_thread_failure
        self.pending: collections.deque = collections.deque()
        self.submitted = start
        self.waited = 0.0

    def _fill(self) -> None:
        while self.pool is not None and len(self.pending) < self.prefetch:
            args = (self.recipe, self.config, self.submitted)
            self.pending.append(self.pool.apply_async(_make, (args,)))
            self.submitted += 1

    def __next__(self) -> Clip:
        if self.pool is None:
            clip = make_clip(self.recipe, self.config, self.next_index)
        else:
            self._fill()
            start = time.monotonic()
            clip = self._wait(self.pending.popleft())
            self.waited += time.monotonic() - start
            self._fill()
        self.next_index += 1
        return clip

    def _wait(self, result):
        """A clip's result, or the fault of the pool's result-handler thread once it has died (it
        would never come: the wait had no end)."""
        handler = getattr(self.pool, "_result_handler", None)
        while True:
            try:
                return result.get(RESULT_POLL_SECONDS)
            except multiprocessing.TimeoutError:
                if handler is not None and not handler.is_alive() and not result.ready():
                    fault = _POOL_THREAD_FAILURES.pop(handler, None)
                    raise fault if fault is not None else RuntimeError(
                        "the data workers' result thread ended: no clip can come") from None

    def close(self) -> None:
        """End the workers. Where a pool thread died (starved of memory while a clip came in),
        ``Pool.terminate`` refuses with its own ``AssertionError`` (its result handler gone with
        results pending), which would hide the error being handled under a traceback: its worker
        handler is then stopped and the workers killed and reaped directly."""
        pool, self.pool = self.pool, None
        if pool is None:
            return
        try:
            pool.terminate()
            pool.join()
        except (AssertionError, RuntimeError, OSError):
            handler = getattr(pool, "_worker_handler", None)
            _kill_workers([handler] if handler is not None else [], list(getattr(pool, "_pool", ())))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class ClipPool:
    """The clips a step may draw from; see the module's docstring for the schedule."""

    def __init__(self, recipe: EngineRecipe, config: SensorConfig, *, capacity: int = 48,
                 refresh: int = 4, step: int = 0, workers: int = 1, progress: bool = False):
        if capacity < 1 or refresh < 1:
            raise ValueError("capacity and refresh must be >= 1")
        self.capacity, self.refresh = capacity, refresh
        first = step // refresh                   # clips that already left the pool
        self.source = ClipSource(recipe, config, start=first, workers=workers, prefetch=capacity + 4)
        indices = range(capacity)
        if progress:
            from tqdm import tqdm
            indices = tqdm(indices, desc="fill the clip pool", unit="clip", leave=False)
        try:
            clips = [next(self.source) for _ in indices]
        except BaseException:            # interrupted while filling: no worker outlives the pool
            self.source.close()
            raise
        # clip i lives in slot i % capacity, whatever step the pool was made at
        self.clips: list[Clip] = [clips[(slot - first) % capacity] for slot in range(capacity)]
        self.made = first + capacity              # index of the next clip to enter
        self.law_inputs: dict = {}                # clip index -> its law input (clip_law_input)

    def advance_to(self, step: int) -> None:
        """Let in every clip scheduled up to ``step``."""
        while self.made < self.capacity + step // self.refresh:
            slot = self.made % self.capacity
            self.law_inputs.pop(self.clips[slot].index, None)
            self.clips[slot] = next(self.source)
            self.made += 1

    def close(self) -> None:
        self.source.close()


def clip_law_input(pool, clip: Clip, config: SensorConfig, device: str | torch.device = "cpu"):
    """A noisy clip's input under its sensor's calibration: the :class:`tespike.recon.learning.infer.LawInputs`
    that inference reads a stream through, made as one block of the whole clip (computed at the first
    draw, on ``device``) and kept while the clip is in the pool (``pool.law_inputs``), so a batch holds
    exactly what inference gives a learned method reading the clip's stream with that calibration.
    None for a clip without a dark law (shot noise only, or a clip carrying only mean maps)."""
    calibration = clip.calibration
    if calibration is None or calibration.dark_law is None:
        return None
    made = pool.law_inputs.get(clip.index)
    if made is None:
        from ..learning.infer import LawInputs
        made = pool.law_inputs[clip.index] = LawInputs(clip.words, config, calibration, device=device,
                                                       block=clip.words.shape[0], keep=True)
    return made


def draw_sample(clip: Clip, span: int, crop: int, rng: np.random.Generator, law_light=None):
    """(words (span, c, c), truth (1, c, c), inside (span,), calibration (2, c, c)) at a random key
    moment, crop and flip of ``clip``.

    ``inside`` marks the span's readouts that lie in the clip (the others repeat its first or last);
    ``calibration`` is the crop's (dark, gain): the clip's sensor's, or (0, 1) for shot noise only.
    ``law_light``: the clip's input under its calibration (:func:`clip_law_input`), cut in place of
    the words (the same readouts, crop and flips; the same random numbers drawn).
    """
    K, H, W = clip.words.shape
    key = int(rng.integers(K))
    times = key_span(K, key, span)
    y, x = int(rng.integers(H - crop + 1)), int(rng.integers(W - crop + 1))
    truth = clip.light[key, y:y + crop, x:x + crop][None]
    if clip.dark is None:
        calibration = np.stack([np.zeros((crop, crop), np.float32), np.ones((crop, crop), np.float32)])
    else:
        calibration = np.stack([clip.dark[y:y + crop, x:x + crop], clip.gain[y:y + crop, x:x + crop]])
    flips = [axis for axis in (-1, -2) if rng.integers(2)]
    if law_light is not None:
        seen = law_light(times, np.arange(y, y + crop), np.arange(x, x + crop))
        seen = seen.flip(flips) if flips else seen
    else:
        seen = clip.words[times, y:y + crop, x:x + crop]
        seen = np.ascontiguousarray(np.flip(seen, flips) if flips else seen)
    if flips:
        truth, calibration = np.flip(truth, flips), np.flip(calibration, flips)
    return (seen, np.ascontiguousarray(truth), span_inside(K, key, span), np.ascontiguousarray(calibration))


def draw_batch(pool: ClipPool, config: SensorConfig, span: int, crop: int, batch: int,
               rng: np.random.Generator, device: str = "cpu") -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(decoded light (B, span, c, c), truth (B, 1, c, c), inside (B, span)) from random clips of the pool.

    A noisy clip's input is what inference gives a learned method reading its stream with its
    sensor's calibration (:func:`clip_law_input`); a clip with mean maps only is corrected by them,
    ``(x - dark) / gain`` (:func:`tespike.recon.learning.infer.frame`); a clip of shot noise only
    passes unchanged (its calibration is dark 0, gain 1)."""
    samples = []
    for _ in range(batch):
        clip = pool.clips[int(rng.integers(len(pool.clips)))]
        samples.append(draw_sample(clip, span, crop, rng, clip_law_input(pool, clip, config, device)))
    seen, truth, inside, calibration = zip(*samples)
    truth, inside, calibration = np.stack(truth), np.stack(inside), np.stack(calibration)
    coded = [b for b, part in enumerate(seen) if isinstance(part, np.ndarray)]
    light = torch.empty((batch, span, crop, crop), dtype=torch.float32, device=device)
    if coded:
        decoded = decode_light(np.stack([seen[b] for b in coded]), config, device=device, dtype=torch.float32)
        mean_only = calibration[coded]
        if (mean_only[:, 0] != 0).any() or (mean_only[:, 1] != 1).any():
            dark, gain = torch.from_numpy(np.ascontiguousarray(mean_only)).to(device)[:, :, None].unbind(1)
            decoded = correct_input(decoded, (dark, 1 / gain))
        light[coded] = decoded
    for b, part in enumerate(seen):
        if not isinstance(part, np.ndarray):
            light[b] = part.to(device)
    return light, torch.from_numpy(truth).to(device), torch.from_numpy(inside).to(device)
