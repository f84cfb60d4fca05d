"""Argument blocks several sub-commands share, so their names and help read the same everywhere."""

from tespike.golden.config import PRESETS

CONFIG_HELP = ("JSON config file, or a preset: " + " / ".join(PRESETS)
               + " (a preset's name is the preset: write ./te for a file named te)")


def add_config_argument(parser, *, required: bool = True, default: str | None = None) -> None:
    """``--config``: a JSON file or one of SPEC's presets."""
    parser.add_argument("--config", required=required, default=default,
                        help=CONFIG_HELP + (f" (default {default})" if default else ""))


def option_typed(parser, token: str) -> str | None:
    """The option of ``parser`` a command-line ``token`` names as argparse reads it: its spelling
    (``--out`` or ``--out=x``), or an unambiguous prefix argparse takes for it (``--conf`` for
    ``--config``); None for anything else (a value, an unknown or ambiguous name)."""
    name = token.split("=", 1)[0]
    every = [option for action in parser._actions for option in action.option_strings]
    if name in every:
        return name
    if name.startswith("--") and parser.allow_abbrev:
        whole = [option for option in every if option.startswith(name)]
        return whole[0] if len(whole) == 1 else None
    return None


def options_given(parser, args, keep=()) -> list[tuple[str, str]]:
    """(flag, dest) of every option of ``parser`` that ``args`` holds away from its default, or
    that its command line (``args.argv``) names even at its default value (an abbreviation too),
    those whose dest is in ``keep`` aside: the options a mode that takes no others would drop. The
    defaults are the parser's own, so they are typed once."""
    typed = {option_typed(parser, token) for token in getattr(args, "argv", None) or () if token.startswith("-")}
    return [(action.option_strings[0], action.dest) for action in parser._actions   # (argparse lists
            if action.option_strings and action.dest not in keep                   # no other way)
            and (getattr(args, action.dest, action.default) != action.default
                 or typed & set(action.option_strings))]


def add_array_arguments(parser, *, required: bool = True, what: str = "", lanes_use: str = "") -> None:
    """``--height``, ``--width`` and ``--lanes``: the generated pixel array and which top (SPEC section 6) a
    command writes, synthesises or tests; ``what`` ends the size help (a limit, or what else it needs),
    ``lanes_use`` says what the command does with the streaming top."""
    parser.add_argument("--height", required=required, type=int, default=None, help=f"pixel rows H >= 1{what}")
    parser.add_argument("--width", required=required, type=int, default=None, help=f"pixel columns W >= 1{what}")
    parser.add_argument("--lanes", type=int, default=None,
                        help="the streaming top (SPEC section 6): N words per beat in raster order, "
                             "N >= ceil(H * W / L) so one interval's beats fit in one readout interval"
                             f"{lanes_use}; without it the parallel top")


#: Suffixes of the files a command writes, by format (:func:`tespike.golden.paths.check_format`):
#: a .npy array (scene, stimulus, reconstruction), a .npz archive (stream, calibration), torch weights.
NPY_FILE = (".npy",)
NPZ_FILE = (".npz",)
TORCH_FILE = (".pt", ".pth")


#: Largest parallel top a command writes, synthesises or tests: 65536 pixels. Its charge and frame
#: ports are H * W * E and H * W * Wd bits wide (up to 2^21 bits at E = 32); larger arrays take
#: minutes to convert and give ports beyond what the simulators here read well.
MAX_PIXELS = 1 << 16

#: Largest streaming top (``--lanes``): 262144 pixels (e.g. 512 x 512), beyond the paper's
#: 400 x 250 sensor. Its Verilog has no port or literal that grows with the words (only
#: ``charge``, H * W * E bits, as SPEC section 6 fixes), and Verilator builds it in time that
#: grows with H + W (docs/outside-simulators.md, "Sensor size").
MAX_STREAM_PIXELS = 1 << 18


def check_array_arguments(config, height, width, lanes) -> tuple[int, int]:
    """Refuse ``--height``, ``--width`` and ``--lanes`` of a generated top in one line naming the flag:
    sizes not integers >= 1, more pixels than the top's limit (MAX_PIXELS, MAX_STREAM_PIXELS with
    ``--lanes``), lanes whose beats do not fit a readout interval (SPEC section 6). -> (height, width)."""
    from tespike.golden.beats import check_lanes
    from tespike.golden.errors import InputError
    for flag, value in (("--height", height), ("--width", width)):
        if type(value) is not int or value < 1:
            raise InputError(f"{flag} {value}: must be an integer >= 1")
    pixels = height * width
    limit, example = (MAX_PIXELS, "256 x 256") if lanes is None else (MAX_STREAM_PIXELS, "512 x 512")
    if pixels > limit:
        raise InputError(f"--height {height} x --width {width} = {pixels} pixels: at most {limit} "
                         f"(e.g. {example}) are supported" + ("" if lanes is None else " with --lanes"))
    if lanes is not None:
        try:
            check_lanes(config, height, width, lanes)
        except ValueError as exc:                      # ConfigError "lanes = N: ...": name the flag
            raise InputError(f"--lanes {lanes}: {str(exc).partition(': ')[2] or exc}") from None
    return height, width


def add_light_arguments(parser, *, out_help: str, seed_help: str, no_noise_help: str) -> None:
    """The light front end of ``simulate`` and ``stimulus``: config, scene, out, seed, dark current, noise."""
    add_config_argument(parser)
    parser.add_argument("--scene", required=True,
                        help="I.npy: float (K, H, W) light per readout interval, 1.0 = design light")
    parser.add_argument("--out", required=True, help=out_help)
    parser.add_argument("--seed", type=int, default=None, help=seed_help)
    from tespike.golden.light import DARK_CURRENT_MODELS
    parser.add_argument("--dark-current", choices=("none",) + DARK_CURRENT_MODELS, default="none",
                        help="dark current model of the paper's eq. 12 or 13 (default: none)")
    parser.add_argument("--no-noise", action="store_true", help=no_noise_help)
    parser.add_argument("--noise", metavar="N.json",
                        help="sensor non-idealities (dark current and level, DSNU, hot pixels, PRNU, comparator "
                             "offset; docs/simulator.md); default: shot noise only (or --dark-current)")
    parser.add_argument("--sensor-seed", type=int, default=None,
                        help="with --noise: the sensor whose per-pixel maps are used (default 0); streams of "
                             "one sensor seed come from one physical sensor")


def light_front_end(args):
    """The checked light options of ``simulate`` and ``stimulus`` -> the :class:`tespike.golden.noise.Sensor`
    of ``--noise`` (None without it): a negative ``--seed``, and ``--no-noise`` with a random
    ``--dark-current`` or a ``--seed`` it would ignore, refused in one line."""
    from tespike.golden.errors import InputError
    if args.seed is not None and args.seed < 0:
        raise InputError(f"--seed {args.seed}: must be >= 0")
    if args.no_noise and args.dark_current != "none":
        raise InputError(f"--dark-current {args.dark_current} is random; it cannot be combined with --no-noise")
    if args.no_noise and args.seed is not None:
        raise InputError("--seed seeds the noise; with --no-noise nothing is drawn (it would be ignored)")
    return sensor_argument(args)


def config_name(spec: str, taken) -> str:
    """A ``--config`` value's sensor name: the preset, or the JSON file's stem; refused where ``taken``
    holds it already (``prove``, ``dataset``: a second sensor of one name replaced the first)."""
    from pathlib import Path

    from tespike.golden.errors import InputError
    name = spec if spec in PRESETS else Path(spec).stem
    if name in taken:
        raise InputError(f"--config {spec!r}: a sensor named {name!r} is already given (names are the "
                         "presets and the files' stems: rename the file)")
    if spec not in PRESETS and name in PRESETS:      # (evaluate --store reads a sensor's kind by its name)
        from tespike.golden.config import SensorConfig, load_config
        if load_config(spec) != SensorConfig.preset(name):
            raise InputError(f"--config {spec!r} is named as the preset {name!r} but holds another "
                             "configuration: rename the file")
    return name


def sensor_argument(args):
    """The :class:`tespike.golden.noise.Sensor` of ``--noise`` / ``--sensor-seed`` (None without
    ``--noise``), refused in one line where it clashes with ``--dark-current`` or ``--no-noise``."""
    from tespike.golden.errors import InputError
    from tespike.golden.noise import Sensor, load_noise
    if args.noise is None:
        if args.sensor_seed is not None:
            raise InputError("--sensor-seed needs --noise N.json (the maps it draws are the non-idealities')")
        return None
    parser = getattr(args, "command_parser", None)
    typed = parser is not None and "dark_current" in {dest for _, dest in options_given(parser, args)}
    if args.dark_current != "none" or typed:   # (even 'none': the file's dark current would override it)
        raise InputError(f"--dark-current {args.dark_current} with --noise: give the dark current in "
                         f"{args.noise} ('dark_current')")
    noise = load_noise(args.noise)
    if args.sensor_seed is not None and not noise.has_maps:
        raise InputError(f"--sensor-seed {args.sensor_seed} draws the per-pixel maps of --noise {args.noise}, which "
                         "has none (dsnu, hot_pixels, prnu and comparator_offset are 0): it would be ignored")
    if args.no_noise and not noise.is_ideal:
        raise InputError(f"--noise {args.noise} describes random non-idealities; it cannot be combined with "
                         "--no-noise")
    return Sensor(noise, sensor_seed_argument(args.sensor_seed))


def sensor_seed_argument(value: int | None) -> int:
    """``--sensor-seed`` (simulate, stimulus, evaluate): 0 when not given, refused below 0."""
    from tespike.golden.errors import InputError
    if value is not None and value < 0:
        raise InputError(f"--sensor-seed {value}: must be >= 0")
    return 0 if value is None else value


#: Most torch CPU threads any command's ``--threads`` accepts (reconstruct, evaluate, train).
MAX_THREADS = 256


def comma_items(text: str, flag: str) -> list[str]:
    """The items of a comma list option (``--methods tfp,net``), stripped; one line naming the
    flag where an item is empty (``tfp,,net``, a trailing comma) or named twice: neither is
    dropped or run twice without a word."""
    from tespike.golden.errors import InputError
    items = [item.strip() for item in text.split(",")]
    if not any(items):
        return []
    if not all(items):
        raise InputError(f"{flag} {text!r}: an item is empty (a comma too many): give names separated by one comma")
    twice = next((item for i, item in enumerate(items) if item in items[:i]), None)
    if twice is not None:
        raise InputError(f"{flag} {text!r}: {twice!r} is named more than once")
    return items


def metrics_argument(text: str) -> list[str]:
    """The metric names of a ``--metrics`` comma list (``score``, ``evaluate``), each one of
    :data:`tespike.recon.score.METRIC_KEYS`; one line naming the flag and the first unknown name otherwise."""
    from tespike.recon.score import check_metrics
    return list(check_metrics(tuple(comma_items(text, "--metrics")), f"--metrics {text!r}"))


def check_threads_argument(threads: int | None) -> None:
    """Refuse a ``--threads`` outside 1..MAX_THREADS with one line (None: torch's choice)."""
    from tespike.golden.errors import InputError
    if threads is not None and not 1 <= threads <= MAX_THREADS:
        raise InputError(f"--threads {threads}: must be in 1..{MAX_THREADS}")


def decimal(text: str) -> int:
    """An integer as typed on a command line: ASCII digits with one optional sign; ValueError
    otherwise. Python's ``int`` also reads ``1_0`` as 10, `` 7 `` as 7 and other scripts' digits,
    which no option, frame list, crop or size takes as a number without a word."""
    import re
    if not re.fullmatch(r"[+-]?[0-9]+", text):
        raise ValueError(text)
    return int(text)


def number(text: str) -> float:
    """A number as typed on a command line: what Python's ``float`` reads, less the digit
    separators (``1_0.5``), surrounding spaces and other scripts' digits it also reads, and
    numbers past the largest float (``1e400``, which it reads as inf: the refusal then named an
    inf the user never typed)."""
    import math
    if "_" in text or text != text.strip() or not text.isascii():
        raise ValueError(text)
    value = float(text)
    if math.isinf(value) and "inf" not in text.lower():
        raise ValueError(text)
    return value


def frame_range(spec, count: int) -> range:
    """Frames selected by ``--frames a:b`` among ``count`` (a default 0, b default
    ``count``, b excluded): inside the files, never clipped to them (``score``, ``view``)."""
    from tespike.golden.errors import InputError
    if spec is None:
        return range(count)
    parts = spec.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        a, b = (decimal(x.strip()) if x.strip() else None for x in parts)
    except ValueError:
        raise InputError(f"--frames {spec!r}: must be 'a:b' with integers a < b (b excluded)") from None
    a = 0 if a is None else a
    b = count if b is None else b
    if not 0 <= a < b <= count:
        raise InputError(f"--frames {spec!r}: needs 0 <= a < b <= {count} (the files hold {count} frames)")
    return range(a, b)


def check_inputs_outside(args, folder_option: str, inputs: tuple[str, ...]) -> None:
    """Refuse any input file or folder of the command (the options ``inputs``, by their argparse
    names; a configuration preset or ``none`` is no file) that lies inside the output folder of
    ``folder_option`` (``"out"``, ``"work_dir"``), which the run replaces whole: a --weights,
    --scene or --verilog kept there was overwritten by the new folder's files. Only the options
    that name files are read: a word such as the command's name or ``--set default`` was taken
    for a path when a folder of that name existed (``demo --out demo`` refused its second run)."""
    import os

    from tespike.golden.config import PRESETS
    from tespike.golden.errors import InputError
    from tespike.golden.paths import lies_inside
    folder = getattr(args, folder_option)
    if folder is None or not os.path.isdir(folder):
        return
    flag = "--" + folder_option.replace("_", "-")
    for dest in inputs:
        value = getattr(args, dest)
        for item in value if isinstance(value, (list, tuple)) else (value,):
            if item is None or (dest.endswith("config") and str(item) in (*PRESETS, "none")):
                continue
            if os.path.lexists(item) and lies_inside(item, folder):
                raise InputError(f"--{dest.replace('_', '-')} {os.fspath(item)!r} lies inside {flag} {folder!r}, "
                                 "which this run replaces whole: refusing to overwrite an input (move it out)")
