"""The ``eha-hil bench joint`` and ``eha-hil bench log`` verbs (the benchmarks themselves are
in :mod:`hil.bench`)."""

from __future__ import annotations


def add_joint_parser(bsub, common, config, emit) -> None:  # noqa: ANN001 (argparse parts)
    """``eha-hil bench joint`` (registered by :mod:`hil.cli.root`)."""
    from hil.bench.joint import bench_joint
    from hil.cli.args import positive_float
    from hil.output.tables import table

    def cmd(args) -> int:  # noqa: ANN001
        cfg = config(args)
        r = bench_joint(cfg, args.seconds)
        text = table(["path", "simulated [s]", "wall [s]", "CPU [s]", "real-time factor (wall)",
                      "real-time factor (CPU)"],
                     [("hip joint stack", r.simulated_s, r.wall_s, r.cpu_s,
                       r.real_time_factor, r.cpu_real_time_factor)], fmt=".3g",
                     title="PC joint loop 1 kHz + fieldbus + MCU 5 kHz + 2 driver boards + "
                     f"2 plants + thigh at 20 kHz, {cfg.sources[-1]}")
        emit(args, text, {"config": cfg.sources, "simulated_s": r.simulated_s,
                          "wall_s": r.wall_s, "cpu_s": r.cpu_s,
                          "real_time_factor": r.real_time_factor,
                          "cpu_real_time_factor": r.cpu_real_time_factor})
        return 0

    p = bsub.add_parser("joint", parents=[common(plot=False)],
                        help="real-time factor of the hip joint stack (PC loop to the thigh)")
    p.add_argument("--seconds", type=positive_float(600, "s"), default=1.0,
                   help="simulated seconds, in (0, 600]")
    p.set_defaults(func=cmd)


def cmd_bench_log(args, cfg) -> int:  # noqa: ANN001
    """``eha-hil bench log``."""
    from hil.bench.log import bench_encodings, bench_overhead, format_report
    from plant.config import load_config

    cfg = cfg or load_config(None)
    ov = None if args.seconds == 0 else bench_overhead(cfg, args.seconds, args.level,
                                                       args.pairs)
    print(format_report(ov, bench_encodings(args.samples)))
    return 0


def add_log_parser(bsub, common, config_fn, wrap) -> None:  # noqa: ANN001
    """Register ``bench log`` on the ``bench`` subparsers."""
    from hil.cli.args import float_range, int_range

    p = bsub.add_parser("log", parents=[common(plot=False)],
                        help="what --log costs bus run (CPU and wall, logged / bare), and "
                        "protobuf against JSON for the decoded signals")
    p.add_argument("--seconds", type=float_range(0.0, 600, unit="s"), default=1.0,
                   help="simulated seconds per run, in [0, 600]; 0: only the encodings")
    p.add_argument("--level", default="mcu", choices=("bus", "mcu", "full"),
                   help="log level of the logged runs")
    p.add_argument("--pairs", type=int_range(1, 50), default=3,
                   help="bare/logged pairs, 1..50")
    p.add_argument("--samples", type=int_range(10, 1_000_000), default=5000,
                   help="samples for the encoding comparison")
    p.set_defaults(func=wrap(cmd_bench_log, config_fn))
