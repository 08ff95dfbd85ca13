"""A seed sweep: the path tracer against BDPT on one scene at several time budgets.

Each integrator renders the scene for each budget with several seeds; each image's relMSE
against a high-sample-count render of the same scene is averaged over the seeds. Prints a
table, and with matplotlib installed and --plot FILE draws relMSE against time.

    python python/examples/seed_sweep.py scenes/cornell-box/scene.xml --size 64 --seeds 5
"""

import argparse
import statistics

import pcbpt


def main() -> None:
    args = arguments()
    scene = pcbpt.load(args.scene, resx=args.size, resy=args.size)
    # The reference: many samples, and a seed none of the sweep's renders uses.
    reference, stats = pcbpt.render(
        scene, args.reference_integrator, spp=args.reference_spp, seed=10_000, threads=args.threads, stats=True
    )
    print(f"reference: {args.reference_integrator}, {args.reference_spp} spp in {stats['render']['seconds']:.1f} s")
    rows = []
    for integrator in args.integrators:
        for seconds in args.budgets:
            errors, spp = [], []
            for seed in range(1, args.seeds + 1):
                image, stats = pcbpt.render(scene, integrator, time=seconds, seed=seed, threads=args.threads, stats=True)
                errors.append(pcbpt.compare(reference, image, "relmse"))
                spp.append(stats["render"]["spp"])
            rows.append((integrator, seconds, statistics.mean(spp), statistics.mean(errors), statistics.stdev(errors)))
    print_table(rows, args.seeds)
    if args.plot:
        plot(rows, args.plot)


def arguments() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene")
    p.add_argument("--size", type=int, default=64, help="film width and height (the resx/resy defaults)")
    p.add_argument("--integrators", nargs="+", default=["path", "bdpt"])
    p.add_argument("--budgets", nargs="+", type=float, default=[0.25, 0.5, 1.0, 2.0], help="seconds per render")
    p.add_argument("--seeds", type=int, default=5, help="renders per integrator and budget (seeds 1..N)")
    p.add_argument("--reference-integrator", default="bdpt")
    p.add_argument("--reference-spp", type=int, default=1024)
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--plot", metavar="FILE", help="draw relMSE against time into FILE (needs matplotlib)")
    return p.parse_args()


def print_table(rows, seeds: int) -> None:
    print(f"\n| integrator | seconds | mean spp | relMSE (mean of {seeds} seeds) | std. dev. |")
    print("|---|---|---|---|---|")
    for integrator, seconds, spp, mean, sd in rows:
        print(f"| {integrator} | {seconds:g} | {spp:.0f} | {mean:.5f} | {sd:.5f} |")


def plot(rows, path: str) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plot")
        return
    fig, ax = plt.subplots(figsize=(5, 4))
    for integrator in dict.fromkeys(r[0] for r in rows):
        mine = [r for r in rows if r[0] == integrator]
        ax.errorbar([r[1] for r in mine], [r[3] for r in mine], yerr=[r[4] for r in mine], marker="o", label=integrator)
    ax.set(xscale="log", yscale="log", xlabel="seconds", ylabel="relMSE")
    ax.legend()
    fig.savefig(path, bbox_inches="tight")
    print(f"plot: {path}")


if __name__ == "__main__":
    main()
