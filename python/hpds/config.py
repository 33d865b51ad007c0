"""A config given as a dict, turned into YAML text for the core's own loader.

The dict has config/hpds.yaml's layout ({"hierarchy": {"cell_size": 0.5}, "normals": {"enabled": True}}). Every
key and every string is written as a double-quoted YAML string, numbers and booleans as plain scalars, so the C++
loader sees what the user gave: an unknown key, a wrong type or a quoted number is reported exactly as it would be
in a YAML file, with the dotted key named.
"""
import json
import math
import numbers


def _scalar(value, key):
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):  # NumPy scalars
        if getattr(value, "size", 1) != 1:
            raise TypeError("config: %s: expected one value, got an array of %d" % (key or "(document)", value.size))
        value = value.item()
        if isinstance(value, bool):
            return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        value = float(value)
        if math.isnan(value):
            return ".nan"
        if math.isinf(value):
            return ".inf" if value > 0 else "-.inf"
        return repr(value)  # the shortest text that reads back as the same double
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a YAML double-quoted scalar
    raise TypeError("config: %s: unsupported value type %s" % (key or "(document)", type(value).__name__))


def _node(value, key, indent):
    if type(value).__module__ == "numpy" and hasattr(value, "tolist"):
        value = value.tolist()  # an array becomes a (nested) list, a NumPy scalar a Python one
    if isinstance(value, dict):
        if not value:
            return " {}\n"
        lines = ["\n"]
        for k, v in value.items():
            if not isinstance(k, str):
                raise TypeError("config: %skeys must be strings, got %r" % (key + ": " if key else "", k))
            lines.append("%s%s:%s" % ("  " * indent, json.dumps(k), _node(v, key + "." + k if key else k, indent + 1)))
        return "".join(lines)
    if isinstance(value, (list, tuple)):
        for v in value:
            if isinstance(v, (list, tuple, dict)):
                raise TypeError("config: %s: nested lists and maps are not config values" % (key or "(document)"))
        return " [" + ", ".join(_scalar(v, key) for v in value) + "]\n"
    return " " + _scalar(value, key) + "\n"


def to_yaml(config):
    """YAML text of a config dict (see the module docstring)."""
    if not isinstance(config, dict):
        raise TypeError("config: expected a dict, a YAML file path or None, got %s" % type(config).__name__)
    if not config:
        return ""
    return _node(config, "", 0).lstrip("\n")
