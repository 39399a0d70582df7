"""``sslpv-harness scenes``: the suite, one line per scene."""

HELP = "list the scene suite, one line each"


def configure(sp):
    pass


def run(args):
    from harness.scene import list_scenes, load_scene

    rows = []
    for name in list_scenes():
        s = load_scene(name)
        rows.append({"name": name, "boundary": s.boundary.kind, "lights": len(s.lights),
                     "grid": list(s.medium.resolution), "size": [s.camera.width, s.camera.height],
                     "hash": s.content_hash[:12], "description": s.description})
    width = max(len(r["name"]) for r in rows) if rows else 4
    text = "\n".join(f"{r['name']:<{width}}  {r['boundary']:<13} {r['lights']} light{'s' if r['lights'] > 1 else ' '} "
                     f"{r['hash']}  {r['description']}" for r in rows)
    return {"scenes": rows}, text, 0
