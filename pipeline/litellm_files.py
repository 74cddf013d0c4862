"""What the installed litellm's own data files say about providers, read without importing litellm.

Why: importing litellm costs seconds of CPU (hundreds of modules, pydantic models), and a
``recap run``/``recap estimate`` that refuses a sweep file should answer in a fraction of
that. The provider names litellm routes (``litellm.provider_list``: the values of its
``LlmProviders`` enum in ``litellm/types/utils.py``), its OpenAI-like providers
(``llms/openai_like/providers.json``), the OpenAI-compatible endpoints it recognises by
``api_base`` (``constants.py``), its model map (``model_prices_and_context_window_backup.json``,
the copy litellm itself loads under ``LITELLM_LOCAL_MODEL_COST_MAP=True``) and its routing rules
(the map's ``fallback_generalizations``) are files of the installed package: they are read here
as text (``ast`` for the Python ones), the package located with :func:`importlib.util.find_spec`,
which does not execute ``litellm/__init__``.

The answers are used only where they are certain (:func:`provider_names`: a provider prefix
litellm knows; :func:`surely_unroutable`: a model string no route of litellm's
``get_llm_provider`` can take); every other question still goes to litellm itself
(:mod:`pipeline.preflight`). Anything unreadable (another layout in a later litellm) answers
"not known here" (None / False), never a guess; tests compare both answers with litellm's own.
"""

from __future__ import annotations

import ast
import importlib.util
import json
import os
import re
from functools import lru_cache
from pathlib import Path
from typing import Any
from urllib.parse import urlparse

#: the litellm files read here, relative to its package folder
ENUM_FILE = "types/utils.py"
JSON_PROVIDERS_FILE = "llms/openai_like/providers.json"
CONSTANTS_FILE = "constants.py"
MODEL_MAP_FILE = "model_prices_and_context_window_backup.json"
#: the files whose string literals name model ids and prefixes ``get_llm_provider`` routes by hand
ROUTING_SOURCES = ("__init__.py", "litellm_core_utils/get_llm_provider_logic.py")


@lru_cache(maxsize=1)
def package_dir() -> Path | None:
    """The installed litellm package folder (not imported), or None when litellm is not installed."""
    try:
        spec = importlib.util.find_spec("litellm")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    return Path(next(iter(spec.submodule_search_locations)))


def _read(rel: str) -> str | None:
    root = package_dir()
    if root is None:
        return None
    try:
        return (root / rel).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None


def _class_strings(tree: ast.Module, name: str) -> list[str] | None:
    """The string values assigned in the body of class ``name`` (an enum of plain string members)."""
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and node.name == name:
            values: list[str] = []
            for stmt in node.body:
                value = stmt.value if isinstance(stmt, (ast.Assign, ast.AnnAssign)) else None
                if isinstance(value, ast.Constant) and isinstance(value.value, str):
                    values.append(value.value)
                elif isinstance(stmt, (ast.Assign, ast.AnnAssign)):
                    return None  # a member that is not a plain string: not readable here
            return values or None
    return None


@lru_cache(maxsize=1)
def provider_names() -> frozenset[str] | None:
    """The values of ``litellm.provider_list`` (its ``LlmProviders`` enum), or None when unreadable."""
    text = _read(ENUM_FILE)
    if text is None:
        return None
    try:
        values = _class_strings(ast.parse(text), "LlmProviders")
    except SyntaxError:
        return None
    return frozenset(values) if values else None


@lru_cache(maxsize=1)
def json_provider_names() -> frozenset[str] | None:
    """The OpenAI-like providers litellm loads from its JSON file (routed by prefix too), or None."""
    root = package_dir()
    if root is None:
        return None
    path = root / JSON_PROVIDERS_FILE
    if not path.exists():
        return frozenset()  # litellm too runs without the file
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return frozenset(data) if isinstance(data, dict) else None


@lru_cache(maxsize=1)
def endpoint_hosts() -> frozenset[str] | None:
    """The host names of ``openai_compatible_endpoints`` (lower case), or None when unreadable."""
    text = _read(CONSTANTS_FILE)
    if text is None:
        return None
    try:
        tree = ast.parse(text)
    except SyntaxError:
        return None
    names: dict[str, str] = {}
    endpoints: ast.expr | None = None
    for node in tree.body:
        target = node.target if isinstance(node, ast.AnnAssign) else node.targets[0] if isinstance(node, ast.Assign) else None
        value = node.value if isinstance(node, (ast.Assign, ast.AnnAssign)) else None
        if not isinstance(target, ast.Name) or value is None:
            continue
        if isinstance(value, ast.Constant) and isinstance(value.value, str):
            names[target.id] = value.value
        if target.id == "openai_compatible_endpoints":
            endpoints = value
    if not isinstance(endpoints, ast.List):
        return None
    hosts: set[str] = set()
    for item in endpoints.elts:
        if isinstance(item, ast.Constant) and isinstance(item.value, str):
            text_value = item.value
        elif isinstance(item, ast.Name) and item.id in names:
            text_value = names[item.id]
        else:
            return None
        host = _host(text_value)
        if host is None:
            return None
        hosts.add(host)
    return frozenset(hosts)


def _host(value: str) -> str | None:
    """The host name of an endpoint or ``api_base`` as litellm parses it (a scheme added when missing)."""
    try:
        host = urlparse(value if "://" in value else f"https://{value}").hostname
    except ValueError:
        return None
    return host.lower() if host else None


@lru_cache(maxsize=1)
def _model_map() -> dict[str, Any] | None:
    text = _read(MODEL_MAP_FILE)
    if text is None:
        return None
    try:
        data = json.loads(text)
    except ValueError:
        return None
    return data if isinstance(data, dict) else None


@lru_cache(maxsize=1)
def _routing_patterns() -> list[re.Pattern[str]] | None:
    """Every rule pattern of the map's ``fallback_generalizations`` (routing or not: any match defers)."""
    data = _model_map()
    if data is None:
        return None
    block = data.get("fallback_generalizations", {})
    rules = block.get("rules", []) if isinstance(block, dict) else None
    if not isinstance(rules, list):
        return None
    patterns: list[re.Pattern[str]] = []
    for rule in rules:
        pattern = rule.get("pattern") if isinstance(rule, dict) else None
        if not isinstance(pattern, str):
            return None
        try:
            patterns.append(re.compile(pattern, re.IGNORECASE))
        except re.error:
            return None
    return patterns


@lru_cache(maxsize=1)
def _routing_sources() -> str | None:
    texts = [_read(rel) for rel in ROUTING_SOURCES]
    return None if any(t is None for t in texts) else "\n".join(t for t in texts if t is not None)


def surely_unroutable(model: str, api_base: str | None, also_known: frozenset[str] = frozenset()) -> bool:
    """True only when litellm's ``get_llm_provider(model, api_base=api_base)`` must fail, decided
    from its files: ``model`` is ``prefix/rest`` with a prefix that is no provider of litellm's (nor
    of ``also_known``, the providers registered at run time), ``api_base`` is none of its known
    endpoints' hosts, the model is no key of its model map, matches none of its routing rules, and
    appears in none of the sources that route model ids by hand. False means "ask litellm"."""
    if os.environ.get("LITELLM_LOCAL_MODEL_COST_MAP", "").lower() != "true" or os.environ.get("USE_LITELLM_PROXY"):
        return False  # litellm would load another map or route everything to its proxy
    prefix, slash, _ = model.partition("/")
    providers, json_providers = provider_names(), json_provider_names()
    if not slash or providers is None or json_providers is None:
        return False
    if prefix in providers or prefix in json_providers or prefix in also_known or ":" in model:
        return False
    if api_base is not None:
        hosts = endpoint_hosts()
        base_host = _host(api_base)
        if hosts is None or base_host is None or base_host in hosts:
            return False
    data, patterns, sources = _model_map(), _routing_patterns(), _routing_sources()
    if data is None or patterns is None or sources is None:
        return False
    lowered = model.lower()
    if lowered in data or any(k.lower() == lowered for k in data):
        return False
    if any(p.search(model) for p in patterns):
        return False
    return f'"{prefix}' not in sources and f"'{prefix}" not in sources and model not in sources
