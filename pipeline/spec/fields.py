"""The building blocks of the sweep schema: checked string and number field types, path and URI helpers.

Every check raises a ValueError whose text pydantic turns into the one-line refusal that names the
field (``models[0].label: may hold only letters, ...``); the schema (:mod:`pipeline.spec.schema`)
puts them together.
"""

from __future__ import annotations

import ipaddress
import os
import re
import unicodedata
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field

from pipeline.spec.bounds import LIST_MAX, NAME_MAX, PATH_MAX, SELECTOR_MAX

#: run names: what a run folder and its tables are called
RUN_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")
#: labels (models, methods): what is printed in tables and unit keys
_LABEL = re.compile(r"^[A-Za-z0-9 _.:@+/(),=#%\-]+$")
#: litellm model strings: printable ASCII without space, brackets or backslash
_MODEL = re.compile(r"^[\x21-\x5a\x5e-\x7e]+$")
#: an environment variable's name (``api_key_env``)
ENV_VAR = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

#: models served in-process by the gateway's test-double provider (no key, no real spend)
OFFLINE_PREFIX = "offline/"

#: object-store schemes an output may use (``file://`` is a local folder)
URI_SCHEMES = ("file", "s3", "gs", "gcs", "hdfs", "abfs", "abfss")

#: the last word of a variable name that holds a credential (``OPENAI_API_KEY``, ``HF_TOKEN``,
#: ``WATSONX_APIKEY``); every key variable litellm reads for a provider ends in one of them
CREDENTIAL_WORDS = ("KEY", "APIKEY", "TOKEN", "SECRET", "PASSWORD", "PASSWD")


def credential_name(name: str) -> bool:
    """Whether an environment variable's name says it holds a credential: it is one of
    :data:`CREDENTIAL_WORDS` or ends in ``_`` and one of them (case-insensitive). ``HOME``,
    ``PATH`` or ``AZURE_API_BASE`` do not, so ``api_key_env`` cannot send them to a provider."""
    upper = name.upper()
    return any(upper == w or upper.endswith("_" + w) for w in CREDENTIAL_WORDS)


def _not_bool(v: object) -> object:
    if isinstance(v, bool):
        raise ValueError("must be a number, not true/false")
    return v


#: numbers in a sweep file are numbers: YAML's true/false are refused, not read as 1/0
NOT_BOOL = BeforeValidator(_not_bool)


def unprintable(v: str) -> str | None:
    """The first character a terminal would interpret (control, format, line separators)."""
    for ch in v:
        if unicodedata.category(ch)[0] == "C" or unicodedata.category(ch) in ("Zl", "Zp"):
            return ch
    return None


def printable(v: str) -> str:
    """``v`` unchanged, or a ValueError naming its first control character."""
    bad = unprintable(v)
    if bad is not None:
        raise ValueError(f"must not contain control characters (found {bad!r})")
    return v


def _label(v: str) -> str:
    if v != v.strip():
        raise ValueError("must not start or end with a space")
    if not _LABEL.match(v):
        raise ValueError(
            f"may hold only letters, digits, spaces and - _ . : @ + / ( ) , = # % (no brackets or control characters), got {v!r}"
        )
    return v


def model_string(v: str) -> str:
    """``v`` unchanged when it can be a litellm model string, else a ValueError."""
    if not _MODEL.match(v):
        raise ValueError(f"must be a litellm model string (printable, no spaces, brackets or backslashes), got {v!r}")
    return v


Name = Annotated[str, Field(min_length=1, max_length=NAME_MAX), AfterValidator(printable)]
Label = Annotated[str, Field(min_length=1, max_length=NAME_MAX), AfterValidator(_label)]
Selector = Annotated[str, Field(min_length=1, max_length=SELECTOR_MAX), AfterValidator(printable)]


def local_path(v: str) -> str:
    """``~`` expanded and made absolute (normalised, symlinks kept), once for every component."""
    p = os.path.expanduser(v)
    if p.startswith("~"):
        raise ValueError(f"cannot expand {v!r} (no such user or no home folder)")
    return os.path.abspath(p)


def is_uri(v: str) -> bool:
    """Whether a location is a URI (``s3://...``, ``file://...``) rather than a local path."""
    return "://" in v


def path_option(key: str) -> bool:
    """Whether an environment option names a folder (``data_dir`` and every ``*_dir``)."""
    return key.startswith("data_dir") or key.endswith("_dir")


def check_free_form(v: dict[str, Any], what: str) -> dict[str, Any]:
    """A free-form mapping (params, options, settings): at most LIST_MAX printable string keys."""
    if len(v) > LIST_MAX:
        raise ValueError(f"at most {LIST_MAX} {what}")
    for k in v:
        if not isinstance(k, str) or not k or len(k) > NAME_MAX or unprintable(k) is not None:
            raise ValueError(f"{k!r} is not a valid key (at most {NAME_MAX} printable characters)")
    return v


class StrictModel(BaseModel):
    """Every section of the sweep file: unknown keys refused, frozen, finite floats, bounded strings."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, str_max_length=PATH_MAX)


_HOST_LABEL = r"[A-Za-z0-9](?:[A-Za-z0-9\-]{0,61}[A-Za-z0-9])?"
#: ``host:port`` or ``ray://host:port`` (a bracketed IPv6 host allowed)
RAY_ADDRESS = re.compile(
    rf"^(?:ray://)?(?P<host>{_HOST_LABEL}(?:\.{_HOST_LABEL})*|\[[0-9A-Fa-f:.%A-Za-z]+\]):(?P<port>\d{{1,5}})$"
)


def check_ray_address(v: str) -> str:
    """``auto``, ``local``, ``host:port`` or ``ray://host:port`` with a port in 1..65535."""
    if v in ("auto", "local"):
        return v
    m = RAY_ADDRESS.match(v)
    ok = m is not None and 1 <= int(m["port"]) <= 65535
    if m is not None and ok and m["host"].startswith("["):
        try:
            ipaddress.IPv6Address(m["host"][1:-1])
        except ValueError:
            ok = False
    if not ok:
        raise ValueError(f"must be auto, host:port or ray://host:port with a port in 1..65535, got {v!r}")
    return v


def field_path(loc: tuple[Any, ...]) -> str:
    """A field's location as the refusal names it: ``models[0].prices.input``."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out
