"""Make docs/img/overview.png, the README's picture: the demo pocket half-way through its program,
as `zmap view` draws it (closed stock, heights in mm, the stage and its G-code line).

    .venv/bin/python docs/img/make_overview.py
"""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def main() -> Path:
    from zmap.sim import simulate
    from zmap.view.app import Viewer

    data = ROOT / "data"
    run = simulate(data / "demo_pocket.nc", (0, 0, -10, 40, 30, 0), tools=data / "tools.toml", pitch=0.26,
                   history="treap")
    viewer = Viewer(run)
    caption = viewer.show_stage(run.stage("1/2")).split(" (")[0]
    viewer.plotter.add_text(f"demo_pocket.nc, {caption}", position="upper_left", font_size=11, color="black",
                            name="title")
    out = ROOT / "docs" / "img" / "overview.png"
    viewer.plotter.screenshot(str(out))
    return out


if __name__ == "__main__":
    print(main())
