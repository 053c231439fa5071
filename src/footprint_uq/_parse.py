"""YAML and JSON text of the project's input files (cameras, poses, budgets, registries, configs), parsed
with three guards the standard loaders lack:

* **alias expansion** (YAML): a 472-byte "billion laughs" document (9 anchors of 9 aliases each) is
  ~4e8 nodes once expanded and ran a command out of memory after half a minute.  The composed
  document is measured first (each anchored node counted once per use, in time linear in the
  text) and refused beyond :data:`MAX_NODES`;
* **document size**: beyond :data:`MAX_CHARS` characters a file is refused before parsing;
* **duplicate keys** (YAML and JSON): both loaders keep the last value silently (``tilt_deg: 70``
  after ``tilt_deg: 20``); here a key given twice in one mapping is refused, naming the key.

Errors are :class:`footprint_uq.errors.ConfigError` naming the file (and the key).  A YAML syntax error is a
:class:`YAMLSyntaxError` -- a ``ConfigError`` and a ``yaml.YAMLError`` at once (callers that catch either keep
working) -- naming the file, the line and the column (1-based) and what the parser expected there; JSON
syntax errors stay ``json.JSONDecodeError`` (whose message has the line and column already).
"""

from __future__ import annotations

import json

import yaml

from .errors import ConfigError

__all__ = ["load_yaml", "load_json", "load_yaml_or_json", "MAX_NODES", "MAX_CHARS", "YAMLSyntaxError"]

#: largest number of YAML nodes once aliases are expanded (a 10^6-node file is ~5 MB of text)
MAX_NODES = 1_000_000
#: largest input text, characters (a registry of 100k cameras is ~10 MB)
MAX_CHARS = 64 * 1024 * 1024
_MERGE = "tag:yaml.org,2002:merge"


def _label(where: str, field: str) -> str:
    return f"{where}: {field}" if where else field


class YAMLSyntaxError(ConfigError, yaml.YAMLError):
    """YAML text that does not parse: ``FILE: line L, column C: got PROBLEM, expected valid YAML (CONTEXT)``."""


def _syntax_error(e: yaml.MarkedYAMLError, where: str) -> YAMLSyntaxError:
    mark = e.problem_mark or e.context_mark
    at = f"line {mark.line + 1}, column {mark.column + 1}" if mark is not None else "somewhere"
    context = e.context or ""
    if context and e.context_mark is not None and e.context_mark is not mark:
        context += f" (line {e.context_mark.line + 1}, column {e.context_mark.column + 1})"
    problem = (e.problem or type(e).__name__).strip()
    return YAMLSyntaxError(f"{where or 'input'}: {at}", problem,
                           f"valid YAML syntax{'; ' + context if context else ''}")


def _check_size(text: str, where: str) -> None:
    if len(text) > MAX_CHARS:
        raise ConfigError(where or "input file", f"{len(text)} characters", f"a file of at most {MAX_CHARS} characters")


class _Loader(yaml.SafeLoader):
    """SafeLoader that refuses a key given twice in one mapping (merge keys ``<<`` may be overridden)."""

    where = ""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen = set()
            for key_node, _ in node.value:
                if key_node.tag == _MERGE or not isinstance(key_node, yaml.ScalarNode):
                    continue
                key = self.construct_object(key_node)
                try:
                    if key in seen:
                        raise ConfigError(_label(self.where, str(key)), "given twice",
                                          "each key once (the YAML loader would keep the last value silently)")
                    seen.add(key)
                except TypeError:  # an unhashable key: the base class says so
                    pass
        return super().construct_mapping(node, deep=deep)


def _expanded_nodes(root) -> int:
    """Nodes of a composed YAML document with every alias expanded, computed once per distinct node."""
    memo: dict[int, int] = {}
    stack = [(root, False)]
    while stack:
        node, done = stack.pop()
        if id(node) in memo:
            continue
        kids = ([c for pair in node.value for c in pair] if isinstance(node, yaml.MappingNode)
                else list(node.value) if isinstance(node, yaml.SequenceNode) else [])
        if done:
            memo[id(node)] = min(1 + sum(memo[id(k)] for k in kids), 10 * MAX_NODES)
            continue
        stack.append((node, True))
        stack.extend((k, False) for k in kids if id(k) not in memo)
    return memo[id(root)]


def load_yaml(text: str, where: str = ""):
    """Parse YAML ``text`` (safe loader) with the module's guards; ``where`` names the file in errors."""
    _check_size(text, where)
    loader = _Loader(text)
    loader.where = where
    try:
        try:
            node = loader.get_single_node()
        except yaml.MarkedYAMLError as e:
            raise _syntax_error(e, where) from None
        except RecursionError:
            raise ConfigError(where or "input file", "nested too deeply", "a YAML document of ordinary depth") from None
        if node is None:
            return None
        n = _expanded_nodes(node)
        if n > MAX_NODES:
            raise ConfigError(where or "input file", f"more than {min(n, 10 * MAX_NODES):.3g} values once its "
                              "aliases (*name) are expanded", f"at most {MAX_NODES:g} (a YAML alias bomb?)")
        try:
            return loader.construct_document(node)
        except RecursionError:
            raise ConfigError(where or "input file", "nested too deeply", "a YAML document of ordinary depth") from None
    finally:
        loader.dispose()


def load_json(text: str, where: str = ""):
    """Parse JSON ``text``, refusing a key given twice in one object; ``where`` names the file in errors."""
    _check_size(text, where)

    def pairs(items):
        out = {}
        for k, v in items:
            if k in out:
                raise ConfigError(_label(where, str(k)), "given twice",
                                  "each key once (the JSON parser would keep the last value silently)")
            out[k] = v
        return out

    return json.loads(text, object_pairs_hook=pairs)


def load_yaml_or_json(text: str, where: str = "", *, is_json: bool = False):
    """:func:`load_json` when ``is_json`` (a ``.json`` file), else :func:`load_yaml`."""
    return load_json(text, where) if is_json else load_yaml(text, where)
