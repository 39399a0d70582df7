"""``sslpv-harness scenes``: the suite, one line per scene; ``scenes SCENE``: validate one scene (a name, a
folder or a scene.toml) and print what it holds; ``--schema``: the JSON Schema of ``scene.toml``."""

HELP = "list the scene suite, one line each (or print the scene.toml JSON Schema, or check one scene)"


def configure(sp):
    sp.add_argument("scene", nargs="?", help="validate this one scene and print its summary: a suite scene's name, "
                    "or a scene folder or scene.toml (default: list the whole suite)")
    sp.add_argument("--schema", action="store_true",
                    help="print the JSON Schema of scene.toml (the file reference_scenes/scene.schema.json)")


def _row(s):
    return {"name": s.name, "boundary": s.boundary.kind, "lights": len(s.lights), "grid": list(s.medium.resolution),
            "size": [s.camera.width, s.camera.height], "hash": s.content_hash[:12], "description": s.description,
            "mesh_repair": s.mesh.repair}


def run(args):
    from harness.scene import list_scenes, load_scene

    if args.schema:
        from harness.scene.model import json_schema, schema_text

        return json_schema(), schema_text().rstrip("\n"), 0
    names = [args.scene] if args.scene is not None else list_scenes()
    rows = [_row(load_scene(name)) for name in names]
    width = max(len(r["name"]) for r in rows) if rows else 4
    text = "\n".join(f"{r['name']:<{width}}  {r['boundary']:<13} {r['lights']} light{'s' if r['lights'] > 1 else ' '} "
                     f"{r['hash']}  {r['description']}" for r in rows)
    return {"scenes": rows}, text, 0
