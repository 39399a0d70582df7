"""``sslpv-harness export STORE --out DIR``: a store's results as one flat table, ``DIR/results.csv`` (or
``DIR/results.parquet`` with ``--format parquet``), the names a study's folder uses.

``--out`` is a folder here as on every command. A path that ends in ``.csv`` or ``.parquet`` and is not a
folder is refused with the command that writes it, instead of being read as a file name: a folder may be
called ``x.csv``, and guessing would give ``--out`` two meanings again.
"""

from pathlib import Path

from harness.cli.options import add_out, add_run, add_scenes

HELP = "export a store's results to CSV (or Parquet, with pyarrow) for analysis"

#: ``--format`` -> the file written into ``--out``.
FILES = {"csv": "results.csv", "parquet": "results.parquet"}


def configure(sp):
    sp.add_argument("source", type=Path, help="store.sqlite, or a sweep folder holding one")
    add_out(sp, "the table, as results.csv or results.parquet", required=True)
    sp.add_argument("--format", choices=list(FILES), default="csv",
                    help="csv | parquet (Parquet needs pyarrow) (default: csv)")
    add_run(sp, default="every run")
    add_scenes(sp, default="every scene")


def run(args):
    from harness.cli.report import resolve_store
    from harness.errors import InputError
    from harness.store import Store

    out = Path(args.out)
    if out.suffix.lower() in (".csv", ".parquet") and not out.is_dir():
        fmt = out.suffix.lower().lstrip(".")
        raise InputError("--out", "out", f"{str(out)!r} names a file, but --out is a folder",
                         f"write --out {out.parent} --format {fmt} (it writes {out.parent / FILES[fmt]})")
    scenes = [n.strip() for n in args.scenes.split(",")] if args.scenes is not None else None
    if scenes is not None and not all(scenes):
        raise InputError("--scenes", "scenes", f"empty scene name in {args.scenes!r}",
                         "list scene names separated by commas")
    path = out / FILES[args.format]
    with Store(resolve_store(args.source), readonly=True) as st:
        rows = st.export(path, run_id=args.run, scene=scenes)
    return {"store": str(args.source), "out": str(out), "file": str(path), "rows": rows}, None, 0
