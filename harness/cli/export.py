"""``sslpv-harness export STORE --out results.csv``: a store's results as one flat table."""

from pathlib import Path

HELP = "export a store's results to CSV (or Parquet, with pyarrow) for analysis"


def configure(sp):
    sp.add_argument("source", type=Path, help="store.sqlite or a sweep folder")
    sp.add_argument("--out", type=Path, required=True, help="output file: .csv or .parquet")
    sp.add_argument("--run", type=int, help="only this run id")
    sp.add_argument("--scene", help="only this scene")


def run(args):
    from harness.cli.report import resolve_store
    from harness.store import Store

    with Store(resolve_store(args.source), readonly=True) as st:
        rows = st.export(args.out, run_id=args.run, scene=args.scene)
    return {"store": str(args.source), "out": str(args.out), "rows": rows}, None, 0
