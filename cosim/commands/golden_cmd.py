"""``tespike golden``: the cycle-exact golden model on an explicit per-clock stimulus.

The stimulus file is memory-mapped and streamed through the engine in
whole-readout chunks, so a file larger than memory runs in memory bounded by
the chunk size plus the words (1/L of the stimulus, in the smallest word
dtype). A progress bar on stderr appears for runs of more than a few chunks
when stderr is a terminal (``--progress on`` forces it).
"""

from tespike.golden.sensor import DEFAULT_CHUNK_ELEMENTS

from .common import NPZ_FILE, add_config_argument

HELP = "run the bit-exact golden model on a per-clock electron stimulus E.npy"
#: It draws progress, so it takes --progress (cli adds the flag to such commands only).
PROGRESS = True

#: Runs with more chunks than this show a progress bar on stderr.
PROGRESS_MIN_CHUNKS = 4


def add_arguments(parser):
    add_config_argument(parser)
    parser.add_argument("--stimulus", required=True, help="E.npy: integer (T, H, W) electrons per pixel clock")
    parser.add_argument("--out", required=True, help="S.npz to write: readout words and the full config")
    parser.add_argument("--chunk-elements", type=int, default=None, metavar="N",
                        help=f"pixel clocks x pixels per chunk (bounds memory; default {DEFAULT_CHUNK_ELEMENTS})")


def run(args) -> int:
    import numpy as np

    from tespike.cosim.console import counted, progress_wanted, report
    from tespike.golden.config import load_config
    from tespike.golden.errors import InputError
    from tespike.golden.io import load_stimulus, save_stream, word_dtype
    from tespike.golden.paths import check_outputs
    from tespike.cosim.headroom import require_room
    from tespike.golden.sensor import PixelArrayModel, iter_chunks

    check_outputs({"--out": args.out}, {"--stimulus": args.stimulus, "--config": args.config},
                  {"--out": NPZ_FILE})
    config = load_config(args.config)
    chunk_elements = DEFAULT_CHUNK_ELEMENTS if args.chunk_elements is None else args.chunk_elements
    if chunk_elements < 1:
        raise InputError(f"--chunk-elements {chunk_elements}: must be >= 1")
    stimulus = load_stimulus(args.stimulus, config)
    T, H, W = stimulus.shape
    L = config.clocks_per_readout
    size = (T // L) * H * W * word_dtype(config).itemsize      # the words, in memory and in S.npz
    clocks_per_chunk = max(1, chunk_elements // max(1, H * W * L)) * L
    chunk = min(T, clocks_per_chunk) * H * W * stimulus.itemsize
    require_room(f"the stream of {T // L} readouts of {H} x {W} words", memory=size + chunk,
                 disk={args.out: size})     # one chunk of the stimulus is read into memory at a time
    words = np.empty((T // L, H, W), word_dtype(config))
    chunks = iter_chunks(stimulus, config, chunk_elements)
    show = progress_wanted(args) and (args.progress == "on" or -(-T // clocks_per_chunk) > PROGRESS_MIN_CHUNKS)
    array = PixelArrayModel(config, (H, W))
    done = 0
    from tqdm import tqdm
    with tqdm(total=T // L, unit="readout", desc="golden", disable=not show, leave=False) as shown:
        for chunk in chunks:
            part = array.feed(np.asarray(chunk))
            words[done:done + len(part)] = part
            done += len(part)
            shown.update(len(part))
    save_stream(args.out, words, config)
    report(args, f"wrote {args.out}: {counted(T // L, 'readout')} of {H} x {W} {config.mode.upper()} words")
    return 0
