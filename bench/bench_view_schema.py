"""The viewer's hand-written message schema (glsynth/view/protocol.py) against msgspec and
pydantic doing the same checks: the time to check one message's shape and JSON types, and
what each library weighs (docs/design.md, "The viewer", says which was chosen).

    .venv/bin/python -m pip install msgspec pydantic   # for the bench only
    .venv/bin/python bench/bench_view_schema.py [--calls 20000] [--repeats 7]

Each check takes a camera message (the one a page sends on every move) from its text to
checked fields: the hand schema is protocol.py's depth scan, ``json.loads`` and type checks;
the libraries decode into a tagged union of the six message types with unknown fields
forbidden and strict types. The pose's rigidity check, which follows in every case, is timed
alone. Times are per message, the best of --repeats runs of --calls messages. Writes
bench/results/view_schema.json.
"""

import argparse
import importlib.metadata
import json
import sys
import timeit
import typing
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402

from glsynth.view import protocol  # noqa: E402

MESSAGE = json.dumps({"type": "camera", "pose": [[1.0, 0, 0, 10.0], [0, 1.0, 0, -4.0],
                                                 [0, 0, 1.0, 6.0], [0, 0, 0, 1]],
                      "focal_mm": 24.0, "moving": True})


def hand_check() -> None:
    protocol._depth(MESSAGE)
    data = json.loads(MESSAGE)
    protocol._check_fields(data.pop("type"), data)


def msgspec_check() -> typing.Callable[[], object]:
    import msgspec

    def struct(tag: str, fields: dict[str, type]) -> type:
        return msgspec.defstruct(tag, list(fields.items()), tag=tag, forbid_unknown_fields=True)

    types = [struct("camera", {"pose": list[list[float]], "focal_mm": float, "moving": bool}),
             struct("pass", {"name": str}), struct("inspect", {"x": float, "y": float}),
             struct("lighting", dict.fromkeys(protocol.LIGHTING_FIELDS, float)),
             struct("scene", {"seed": int, "env": int, "quality": str | None,
                              "config_toml": str | None}),
             struct("save", {})]
    decoder = msgspec.json.Decoder(typing.Union[tuple(types)])  # noqa: UP007
    return lambda: decoder.decode(MESSAGE)


def pydantic_check() -> typing.Callable[[], object]:
    import pydantic

    def model(tag: str, fields: dict[str, type]) -> type:
        return pydantic.create_model(
            tag, __config__=pydantic.ConfigDict(extra="forbid", strict=True),
            type=(typing.Literal[tag], ...), **{k: (v, ...) for k, v in fields.items()})

    types = [model("camera", {"pose": list[list[float]], "focal_mm": float, "moving": bool}),
             model("pass", {"name": str}), model("inspect", {"x": float, "y": float}),
             model("lighting", dict.fromkeys(protocol.LIGHTING_FIELDS, float)),
             model("scene", {"seed": int, "env": int, "quality": str | None,
                             "config_toml": str | None}),
             model("save", {})]
    adapter = pydantic.TypeAdapter(typing.Annotated[typing.Union[tuple(types)],  # noqa: UP007
                                                    pydantic.Field(discriminator="type")])
    return lambda: adapter.validate_json(MESSAGE)


def installed_mb(distributions: list[str]) -> float:
    """Size of the installed files of ``distributions``."""
    total = 0
    for name in distributions:
        for file in importlib.metadata.distribution(name).files or []:
            path = Path(file.locate())
            total += path.stat().st_size if path.is_file() else 0
    return total / 2**20


def best_us(fn: typing.Callable[[], object], calls: int, repeats: int) -> float:
    return min(timeit.repeat(fn, number=calls, repeat=repeats)) / calls * 1e6


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--calls", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    pose = json.loads(MESSAGE)["pose"]
    results = {"hand_us": best_us(hand_check, args.calls, args.repeats),
               "pose_check_us": best_us(lambda: protocol.rigid_pose(pose), args.calls,
                                        args.repeats)}
    libraries = {"msgspec": (msgspec_check, ["msgspec"]),
                 "pydantic": (pydantic_check, ["pydantic", "pydantic-core", "annotated-types",
                                               "typing-inspection"])}
    for name, (make, distributions) in libraries.items():
        try:
            check = make()
        except ImportError:
            print(f"{name}: not installed, skipped")
            continue
        results[f"{name}_us"] = best_us(check, args.calls, args.repeats)
        results[f"{name}_version"] = importlib.metadata.version(name)
        results[f"{name}_installed_mb"] = installed_mb(distributions)
    print(json.dumps(results, indent=1))
    write_results("view_schema", results)


if __name__ == "__main__":
    main()
