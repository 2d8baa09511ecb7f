"""The config dataclass machinery: ranges, choices, YAML files, argparse bridge."""
import argparse
from dataclasses import dataclass

import pytest

from aircraft_docking_tracker.config import (
    ConfigError, add_config_arguments, config_from_arguments, from_mapping, load_yaml_parameters,
    param, parse_bool, validate)


@dataclass
class Example:
    rate: float = param(0.5, "a rate", low=0.0, high=1.0)
    count: int = param(10, "a count", low=1, high=100)
    mode: str = param("seed", "a mode", choices=("seed", "gated"))


def test_defaults_validate():
    assert validate(Example()).rate == 0.5


@pytest.mark.parametrize("values, reason", [
    ({"rate": 1.5}, "above its maximum"), ({"count": 0}, "below its minimum"),
    ({"mode": "other"}, "not one of"), ({"rate": float("nan")}, "NaN"), ({"bogus": 1}, "unknown")])
def test_bad_values_are_refused_with_a_reason(values, reason):
    with pytest.raises(ConfigError, match=reason):
        from_mapping(Example, values)


def test_int_is_accepted_for_float_fields():
    assert from_mapping(Example, {"rate": 1}).rate == 1.0


def test_yaml_parameter_file(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text("my_node:\n  ros__parameters:\n    rate: 0.25\n    nested:\n      count: 3\n")
    assert load_yaml_parameters(path, "my_node") == {"rate": 0.25, "nested.count": 3}
    assert load_yaml_parameters(path) == {"rate": 0.25, "nested.count": 3}


def test_argparse_bridge_overrides_yaml():
    parser = argparse.ArgumentParser()
    add_config_arguments(parser, Example)
    args = parser.parse_args(["--count", "7"])
    cfg = config_from_arguments(Example, args, base={"rate": 0.1})
    assert (cfg.rate, cfg.count, cfg.mode) == (0.1, 7, "seed")


def test_boolean_options_read_the_usual_words_and_refuse_others():
    """parse_bool: what a boolean --option (and bench/guidance.py's --set) takes; a typo is refused, not read as
    False."""
    assert [parse_bool(w) for w in ("1", "True", "yes", "ON", "0", "false", "No", "off")] == [True] * 4 + [False] * 4
    with pytest.raises(ValueError):
        parse_bool("flase")

    @dataclass
    class Switch:
        on: bool = param(False, "a switch")

    parser = argparse.ArgumentParser()
    add_config_arguments(parser, Switch)
    assert parser.parse_args(["--on", "true"]).on is True
    with pytest.raises(SystemExit):
        parser.parse_args(["--on", "maybe"])


def test_split_ros_args_keeps_tool_remaps_away_from_rcl():
    from aircraft_docking_tracker.cli import split_ros_args

    own, ros = split_ros_args(["bag.mcap", "--remap", "image:=/cam/image", "--ros-args", "-r", "__ns:=/x",
                               "-p", "a:=1", "--", "--rate", "2"])
    assert own == ["bag.mcap", "--remap", "image:=/cam/image", "--rate", "2"]
    assert ros == ["--ros-args", "-r", "__ns:=/x", "-p", "a:=1"]


def test_wildcard_sections_merge_like_rcl(tmp_path):
    path = tmp_path / "setup.yaml"
    path.write_text("/**:\n  ros__parameters:\n    a: 1\n    b: 1\n"
                    "/**/detector:\n  ros__parameters:\n    b: 2\n    c: 2\n"
                    "/cam0/detector:\n  ros__parameters:\n    c: 3\n"
                    "/**/association:\n  ros__parameters:\n    a: 9\n")
    assert load_yaml_parameters(path, "detector") == {"a": 1, "b": 2, "c": 3}
    assert load_yaml_parameters(path, "association") == {"a": 9, "b": 1}


def test_every_setup_file_names_only_real_parameters():
    """config/*_camera.yaml sections must name parameters that the nodes declare."""
    from aircraft_docking_tracker.config import package_config_dir
    from aircraft_docking_tracker.offline import processor_spec

    for setup in sorted(package_config_dir().glob("*_camera.yaml")):
        for node in ("detector", "association", "docking_tracker"):
            spec = processor_spec(node)
            known = {prefix + name for prefix, cls in spec.configs.items() for name in cls.__dataclass_fields__}
            import yaml
            sections = yaml.safe_load(setup.read_text())
            if f"/**/{node}" not in sections:
                continue
            names = set(load_yaml_parameters(setup, node)) - set(load_yaml_parameters(setup, "__none__"))
            assert names <= known, f"{setup.name}: unknown {node} parameters {sorted(names - known)}"


def test_percent_in_a_description_does_not_break_help():
    @dataclass
    class WithPercent:
        gate: float = param(9.21, "chi-square threshold (99 % of mass)", low=0.0)

    parser = argparse.ArgumentParser()
    add_config_arguments(parser, WithPercent)
    assert "99 % of mass" in parser.format_help()


def test_seed_preset_is_the_seed_configuration():
    from aircraft_docking_tracker.config import package_config_dir
    from aircraft_docking_tracker.offline import processor_spec
    from multi_target_tracker.association import seed_config

    spec = processor_spec("association")
    configs = spec.configs_from_parameters(load_yaml_parameters(package_config_dir() / "association_seed.yaml",
                                                                "association"))
    assert configs[""] == seed_config()
    assert configs["kalman."].acceleration_noise_per_px == 0.0
