"""``sslpv-harness render SCENE --grid N --steps K ... --out DIR``: one SSLPV render."""

from pathlib import Path

from harness.cli.options import add_sslpv_args

HELP = "render a scene with the SSLPV GLSL renderer"


def configure(sp):
    sp.add_argument("scene", help="suite scene name or path")
    sp.add_argument("--out", type=Path, required=True, help="output folder")
    add_sslpv_args(sp, multi=False)


def run(args):
    from harness.runs.params import params_from_cli
    from harness.runs.render import run_render

    params = params_from_cli(vars(args))
    return run_render(args.scene, args.out, params, as_json=args.json), None, 0
