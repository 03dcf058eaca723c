"""Validated configuration: strict readers for the public YAML formats and per-device settings."""

from ppod_ros.config.fields import Fields, check_array, check_number, load_yaml_file, parse_yaml_text

__all__ = ["Fields", "check_array", "check_number", "load_yaml_file", "parse_yaml_text"]
