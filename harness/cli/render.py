"""``sslpv-harness render SCENE [--method M] [--size WxH|small] [--grid N] [--steps K] ... --out DIR``: one
render of one method."""

from harness.cli.options import add_method_args, add_out, add_scene, add_size, add_sslpv_args

HELP = "render a scene with one method (default: the SSLPV GLSL renderer)"


def configure(sp):
    add_scene(sp)
    add_out(sp, "the render (subsurface.exr, full.exr, render.json)", required=True)
    add_size(sp, ("WxH", "small"))
    add_sslpv_args(sp, multi=False)
    add_method_args(sp, multi=False)


def run(args):
    from harness.methods import parse_methods
    from harness.methods.params import all_cli_names, params_from_cli
    from harness.runs.render import run_render
    from harness.runs.sweep import parse_size

    size = parse_size(args.size)                 # a bad value is refused before anything is rendered
    methods = parse_methods(args.method)
    if len(methods) != 1:
        from harness.errors import InputError

        raise InputError("--method", "method", f"render takes one method, got {len(methods)}", "use 'sweep' for lists")
    values = vars(args)
    params = params_from_cli(methods[0], {k: values.get(k) for k in all_cli_names()})
    return run_render(args.scene, args.out, params, as_json=args.json, method=methods[0],
                      size=size), None, 0
