"""``tespike scene``: write a light sequence I.npy (built-in scene or a folder of HDR frames)."""

HELP = "write a light sequence I.npy: a built-in scene by name, or a folder of .exr/.hdr frames"
#: It draws progress, so it takes --progress (cli adds the flag to such commands only).
PROGRESS = True

#: Defaults of a built-in scene's options (refused beside --folder, so they default to None there).
BUILT_IN = {"name": "default", "height": 96, "width": 128, "seed": 0}


def add_arguments(parser):
    parser.add_argument("--name", default=None,
                        help="built-in scene (see --list); default: the shipped panorama, panned")
    parser.add_argument("--folder", help="instead of --name: a folder of .exr/.hdr frames, sorted by name")
    parser.add_argument("--frames", type=int, default=24,
                        help="readout intervals K (default 24; with --folder: at most this many frames)")
    parser.add_argument("--height", type=int, default=None, help=f"rows H (default {BUILT_IN['height']})")
    parser.add_argument("--width", type=int, default=None, help=f"columns W (default {BUILT_IN['width']})")
    parser.add_argument("--seed", type=int, default=None, help=f"random seed (default {BUILT_IN['seed']})")
    parser.add_argument("--peak", type=float, default=1.0,
                        help="brightest pixel of the sequence, in design light (default 1.0)")
    parser.add_argument("--motion", help="camera motion of panorama scenes: pan (default), tilt, rotate, "
                        "zoom or mixed")
    parser.add_argument("--sources", type=int, help="moving bright sources added to a panorama scene")
    parser.add_argument("--grayscale", default=None, help="--folder: luminance weights of the frames, rec709 "
                                                          "(default) or rec601")
    parser.add_argument("--crop", metavar="HxW", help="--folder: centre-crop every frame to H x W (e.g. 384x512)")
    parser.add_argument("--downscale", type=int, default=1,
                        help="--folder: area-average N x N blocks after cropping (default 1)")
    parser.add_argument("--list", action="store_true", help="list the built-in scenes and exit")
    parser.add_argument("--out", help="I.npy to write: float32 (K, H, W), 1.0 = design light")


def run(args) -> int:
    import math

    import numpy as np

    from tespike.cosim.console import progress_wanted, report
    from tespike.golden.errors import InputError
    from tespike.golden.io import atomic_output

    from .common import NPY_FILE, decimal, options_given
    from tespike.golden.paths import check_distinct, check_outputs
    from tespike.cosim.headroom import require_room
    from tespike.recon.scenes import SCENES, load_hdr_sequence, make_scene
    from tespike.recon.scenes.hdr_io import list_frames
    from tespike.recon.scenes.color import DEFAULT_WEIGHTS

    if args.list:
        given = options_given(args.command_parser, args, keep=("list",))         # (the list is the output: no -q)
        if given:
            raise InputError(f"--list prints the built-in scenes and takes no other option ({given[0][0]} given)")
        for name, (_, summary) in SCENES.items():
            print(f"{name:10s} {summary}")
        return 0
    if not args.out:
        raise InputError("--out is required (the I.npy to write)")
    if not args.folder:
        for flag, given in (("--crop", args.crop is not None), ("--downscale", args.downscale != 1),
                            ("--grayscale", args.grayscale is not None)):
            if given:
                raise InputError(f"{flag} applies to --folder only (a built-in scene is made at "
                                 "--height x --width)")
    else:                                               # (a folder's frames fix these)
        for flag, key in (("--name", "name"), ("--height", "height"), ("--width", "width"), ("--seed", "seed"),
                          ("--motion", "motion"), ("--sources", "sources")):
            if getattr(args, key) is not None:
                raise InputError(f"{flag} applies to built-in scenes only (--folder's frames fix the "
                                 "sequence; --crop and --downscale size it)")
    for key, default in BUILT_IN.items():
        if getattr(args, key) is None:
            setattr(args, key, default)
    if not (math.isfinite(args.peak) and args.peak > 0):
        raise InputError(f"--peak {args.peak!r}: must be a finite number > 0")
    crop = None
    if args.folder:
        if args.crop:
            try:
                crop = tuple(decimal(n.strip()) for n in args.crop.lower().split("x"))
            except ValueError:
                crop = ()
            if len(crop) != 2:
                raise InputError(f"--crop {args.crop!r} must be HxW, e.g. 384x512")
        if args.frames < 1:
            raise InputError(f"--frames {args.frames}: must be >= 1")
        # a frame given as --out: the worse fault, named before the output's format
        check_distinct([("a frame of --folder", frame) for frame in list_frames(args.folder)], {"--out": args.out})
    check_outputs({"--out": args.out}, formats={"--out": NPY_FILE})
    if args.folder:
        light = load_hdr_sequence(args.folder, weights=args.grayscale or DEFAULT_WEIGHTS, peak=args.peak,
                                  max_frames=args.frames, crop=crop, downscale=args.downscale,
                                  progress=progress_wanted(args))
    else:
        from tespike.recon.scenes import PANORAMAS, SCENES
        if args.name in SCENES and args.name not in ("default",) + PANORAMAS:   # (the library's refusal names its keyword, not the flag)
            for flag, key in (("--motion", "motion"), ("--sources", "sources")):
                if getattr(args, key) is not None:
                    raise InputError(f"{flag} applies to the panorama scenes only (default, "
                                     f"{', '.join(PANORAMAS)}): scene {args.name!r} takes neither")
        if args.sources is not None and args.sources < 0:
            raise InputError(f"--sources = {args.sources} must be >= 0")
        values = args.frames * args.height * args.width
        spots = 0 if args.sources is None else args.sources   # (a panorama's spots are drawn whole first)
        require_room(f"the scene of {args.frames} x {args.height} x {args.width} values"
                     + (f" with --sources {spots}" if spots else ""), memory=8 * values * (1 + spots),
                     disk={args.out: 4 * values})     # float32 light, and the generator's own copy
        light = make_scene(args.name, args.frames, args.height, args.width, seed=args.seed,
                           peak=args.peak, motion=args.motion, sources=args.sources)
    with atomic_output(args.out) as tmp:
        with open(tmp, "wb") as handle:
            np.save(handle, light)
    K, H, W = light.shape
    report(args, f"wrote {args.out}: {K} frames of {H} x {W} light, peak {float(light.max()):.6g}")
    return 0
