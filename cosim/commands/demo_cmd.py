"""``tespike demo``: the main job on the built-in scene, end to end, in seconds.

Scene (the shipped CC0 panorama, panned) -> TE and ML streams with shot
noise -> TFP and TFI reconstruction -> PSNR-mu / SSIM-mu table (printed and
written) and a tone-mapped strip. Every intermediate file is written too, so
each step can be re-run with the individual commands.
"""

HELP = "run the main job on the built-in scene: scene -> TE/ML streams -> TFP/TFI -> table and strip"


def add_arguments(parser):
    parser.add_argument("--out", default="demo", help="output folder (default ./demo)")
    parser.add_argument("--frames", type=int, default=32, help="readout intervals (default 32)")
    parser.add_argument("--height", type=int, default=96, help="rows (default 96)")
    parser.add_argument("--width", type=int, default=128, help="columns (default 128)")
    parser.add_argument("--seed", type=int, default=0, help="scene and shot-noise seed (default 0)")


def run(args) -> int:
    import time
    from pathlib import Path

    import numpy as np

    from cosim.cli import progress_wanted
    from golden.fastsim import simulate_scene
    from golden.io import atomic_output, save_images, save_stream
    from golden.paths import check_output_dir
    from recon.evaluate import OUTPUT_FILES, evaluate, paper_configs, table_markdown, write_outputs
    from recon.scenes import make_scene

    start = time.perf_counter()
    configs = paper_configs()
    methods = ("tfp", "tfi")
    files = OUTPUT_FILES + ("I.npy",) + tuple(f"S_{m}.npz" for m in configs) + tuple(
        f"R_{method}_{m}.npy" for method in methods for m in configs)
    out = check_output_dir(args.out, "--out", files)      # every file checked before any is written
    light = make_scene("default", args.frames, args.height, args.width, seed=args.seed)
    out.mkdir(parents=True, exist_ok=True)
    with atomic_output(out / "I.npy") as tmp:
        with open(tmp, "wb") as handle:
            np.save(handle, light)
    evaluation = evaluate([("default", light)],
                          lambda config, scene, rng: simulate_scene(config, scene, seed=rng),
                          methods=methods, configs=configs, seed=args.seed, keep=True,
                          progress=progress_wanted(args))
    for mode, config in configs.items():
        save_stream(out / f"S_{mode}.npz", evaluation.streams["default", mode], config)
        for method in methods:
            save_images(out / f"R_{method}_{mode}.npy", evaluation.images["default", mode, method])
    paths = write_outputs(evaluation, out)
    if args.quiet:
        return 0
    print(f"scene: shipped CC0 panorama 'courtyard', panned; {args.frames} readouts of "
          f"{args.height} x {args.width}; TE b1 = b2 = 4, ML 8-bit msb (the paper's ML, eq. 10) and ML 8-bit "
          f"full-count sensors, shot noise, seed {args.seed}")
    print(table_markdown(evaluation), end="")
    print(f"PSNR-mu / SSIM-mu: mu-law (mu = 5000) after division by the ground truth's peak; "
          f"frames {evaluation.window // 2}..{args.frames - 1 - evaluation.window // 2} scored")
    print(f"wrote {out}/: I.npy, S_ml-msb.npz, S_te.npz, S_ml.npz, R_<method>_<mode>.npy, table.md, table.csv, "
          f"results.csv, {paths['plot'].name}, strips/default.png ({time.perf_counter() - start:.1f} s)")
    return 0
