"""The weights file of every learned method: one format, written by one function and read by one.

A weights file is a ``torch.save`` of a plain dictionary, loadable with
``torch.load(weights_only=True)`` (no pickled code): ``method`` (its name in
:data:`tespike.recon.learned.LEARNED`), ``state_dict``, ``sizes`` (the sizes
dataclass's ``to_dict``), ``config`` (the sensor configuration it was trained
for) and ``meta`` (how it was made). Building the module from it is the
registry's (:func:`tespike.recon.learned.load_weights`): this layer knows no method.
"""

from __future__ import annotations

import io
import pickle
import struct
import zipfile
import zlib
from pathlib import Path
from typing import Any

import torch

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, one_line
from tespike.golden.io import atomic_output, check_archive_end, refuse_starved

#: Keys every weights file holds.
PAYLOAD_KEYS = ("state_dict", "sizes", "config")


def cpu_state(model: torch.nn.Module) -> dict[str, torch.Tensor]:
    """A copy of ``model``'s tensors on the CPU (later training does not change it)."""
    return {k: v.detach().to("cpu", copy=True) for k, v in model.state_dict().items()}


def save_weights(path: str | Path, model: torch.nn.Module, config: SensorConfig, meta: dict[str, Any],
                 method: str, state: dict[str, torch.Tensor] | None = None) -> None:
    """Write ``model`` (a learned method's module with its ``sizes``) for ``config``, atomically;
    ``state``: its tensors at another moment (:func:`cpu_state`), instead of its present ones."""
    payload = {"method": method, "state_dict": cpu_state(model) if state is None else state,
               "sizes": model.sizes.to_dict(), "config": config.to_dict(), "meta": meta}
    write_torch_file(path, payload)


def write_torch_file(path: str | Path, payload: Any) -> None:
    """``torch.save`` of ``payload`` to ``path``, atomically, as one plain write: a full disk or a
    vanished folder is a one-line refusal naming ``path`` (torch's own writer reports neither)."""
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    with atomic_output(path) as tmp:
        Path(tmp).write_bytes(buffer.getbuffer())


def _check_crcs(path: str | Path, what: str, kind: str) -> None:
    """Refuse a torch zip archive a member of which fails its CRC (a flipped or lost byte); an
    archive zipfile cannot open at all is left to ``torch.load``, which names its own fault."""
    try:
        archive = zipfile.ZipFile(path)
    except (OSError, zipfile.BadZipFile, ValueError, EOFError) as exc:
        refuse_starved(exc, what, path)                 # (an intact file read without handles is not damaged)
        return
    try:
        with archive:
            check_archive_end(path)
            damaged = archive.testzip()
    except (OSError, zipfile.BadZipFile, ValueError, EOFError, NotImplementedError, zlib.error) as exc:
        refuse_starved(exc, what, path)
        raise InputError(f"{what} {str(path)!r} is not a {kind} (a damaged archive: {one_line(exc, 100)})") from None
    if damaged is not None:
        raise InputError(f"{what} {str(path)!r} is not a {kind} (a damaged archive: member {damaged!r} "
                         "fails its CRC check)")


def read_torch_file(path: str | Path, what: str, kind: str) -> Any:
    """``torch.load(path, weights_only=True)`` on the CPU; a one-line refusal naming ``what`` (a flag or a
    role), the file and the cause where it cannot be read or is no torch file of ``kind``. The
    archive's CRCs are checked first: ``torch.load`` does not, and would load an altered byte. A
    path that is no regular file (a FIFO blocked the command for good) is refused first."""
    from tespike.golden.paths import check_input_file
    check_input_file(path, what)
    _check_crcs(path, what, kind)
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except OSError as exc:
        refuse_starved(exc, what, path)
        raise InputError(f"cannot read {what} {str(path)!r}: {exc.strerror or exc}") from None
    except (RuntimeError, EOFError, ValueError, pickle.UnpicklingError, zipfile.BadZipFile) as exc:
        raise InputError(f"{what} {str(path)!r} is not a {kind} ({_load_fault(path, exc)})") from None
    except (KeyError, IndexError, TypeError, AttributeError, UnicodeDecodeError, struct.error) as exc:
        # torch's loader for files that are not zip archives (its legacy format) reads any bytes
        # as that format's pickle and fails on text with these (e.g. KeyError: 101 on "hello")
        raise InputError(f"{what} {str(path)!r} is not a {kind} ({_load_fault(path, exc)})") from None


def _load_fault(path: str | Path, exc: BaseException) -> str:
    """Why ``torch.load`` refused ``path``, in our words where the file's form says it: torch's own
    first line for a cut-short file speaks of ``weights_only`` defaults or of an internal assert."""
    try:
        if Path(path).stat().st_size == 0:
            return "the file is empty"
        if not zipfile.is_zipfile(path):
            return "not a zip archive as torch writes: cut short, or another format"
    except OSError:
        pass
    text = str(exc)
    if text.startswith("Weights only load failed"):   # (torch's first line advises loading it unsafely)
        lines = [line.strip() for line in text.splitlines()[1:] if line.strip()
                 and not line.startswith(("Check the documentation", "Please file an issue"))]
        what = one_line(lines[0], 200) if lines else "objects other than tensors"
        return f"it holds Python objects a weights file does not ({what}); not loaded, as loading could run code"
    if text.startswith("PytorchStreamReader failed"):  # (miniz: an archive whose directory is damaged)
        return f"a damaged archive: {one_line(text.split('. ')[0], 200)}"
    if "not in a subdirectory" in text:                 # (a zip archive of another kind: an S.npz, a C.npz)
        try:
            with zipfile.ZipFile(path) as archive:
                names = archive.namelist()
            return (f"a zip archive, but not torch's: it holds {one_line(', '.join(names[:4]), 160)}"
                    f"{', ...' if len(names) > 4 else ''}")
        except (OSError, zipfile.BadZipFile):
            pass
    return f"another format: {one_line(text.splitlines()[0] if text else exc, 300)}"


def read_weights(path: str | Path, what: str = "weights") -> dict[str, Any]:
    """The payload of weights file ``path`` (method, state dict, sizes, config as a SensorConfig, meta)."""
    payload = read_torch_file(path, what, "tespike weights file")
    if not isinstance(payload, dict) or any(key not in payload for key in PAYLOAD_KEYS):
        raise InputError(f"{what} {str(path)!r} is not a tespike weights file (no {', '.join(PAYLOAD_KEYS)})")
    try:
        config = SensorConfig.from_dict(payload["config"], whole=True)
    except (InputError, TypeError, ValueError) as exc:
        raise InputError(f"{what} {str(path)!r}: its sensor configuration is not valid ({exc})") from None
    method = payload.get("method", "net")
    if not isinstance(method, str):
        raise InputError(f"{what} {str(path)!r}: its method {method!r} is not a method's name")
    meta = payload.get("meta", {})
    if not isinstance(meta, dict):
        raise InputError(f"{what} {str(path)!r}: its record (meta) is a {type(meta).__name__}, not a mapping")
    return {**payload, "method": method, "config": config, "meta": meta}
