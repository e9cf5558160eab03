"""Which estimators an evaluation runs: names, options and the labels that tell them apart."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = ["MethodSpec", "parse_method_spec", "resolve_methods", "split_method_list"]


@dataclass(frozen=True)
class MethodSpec:
    """One row of an evaluation: a registered method with fixed options.

    Attributes
    ----------
    label : str
        Name in the outputs (unique within an evaluation), e.g. ``"3f2n[aggregate=mean]"``.
    method : str
        A name from :func:`depthnormals.methods` (``"<name>+"`` forms included).
    options : dict
        Keyword options passed to :func:`depthnormals.estimate_normals`; JSON values only.
    """

    label: str
    method: str
    options: dict = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return {"label": self.label, "method": self.method, "options": dict(self.options)}


def _json_value(text: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def split_method_list(text: str) -> list[str]:
    """Split ``"a,b[x=1,y=2],c"`` at the commas outside brackets."""
    if not isinstance(text, str):
        raise TypeError(f"methods must be a comma-separated string; got {type(text).__name__}")
    out, depth, cur = [], 0, []
    for ch in text:
        if ch == "[":
            depth += 1
        elif ch == "]":
            depth -= 1
            if depth < 0:
                raise ValueError(f"unbalanced ']' in method list {text!r}")
        if ch == "," and depth == 0:
            out.append("".join(cur).strip())
            cur = []
        else:
            cur.append(ch)
    if depth:
        raise ValueError(f"unbalanced '[' in method list {text!r}")
    out.append("".join(cur).strip())
    if any(not s for s in out):
        raise ValueError(f"empty method name in method list {text!r}")
    return out


def parse_method_spec(text: str) -> MethodSpec:
    """Parse ``"name"`` or ``"name[key=value,key=value]"`` (values parsed as JSON if they can be).

    The label is the text itself (spaces removed).

    Examples
    --------
    >>> spec = parse_method_spec("3f2n[aggregate=mean,kernel_size=3]")
    >>> spec.method, spec.options
    ('3f2n', {'aggregate': 'mean', 'kernel_size': 3})
    """
    if not isinstance(text, str):
        raise TypeError(f"a method spec must be a string; got {type(text).__name__}")
    label = text.replace(" ", "")
    if not label:
        raise ValueError("empty method spec")
    if "[" not in label:
        if "]" in label:
            raise ValueError(f"method spec {text!r}: ']' without '['")
        return MethodSpec(label, label, {})
    if not label.endswith("]"):
        raise ValueError(f"method spec {text!r} must look like name[key=value,...]")
    name, body = label[:-1].split("[", 1)
    options: dict[str, Any] = {}
    for item in filter(None, body.split(",")):
        if "=" not in item:
            raise ValueError(f"method spec {text!r}: option {item!r} must look like key=value")
        key, value = item.split("=", 1)
        options[key.replace("-", "_")] = _json_value(value)
    return MethodSpec(label, name, options)


def resolve_methods(methods: str | Sequence[str | MethodSpec],
                    method_options: Mapping[str, Mapping[str, Any]] | None = None
                    ) -> list[MethodSpec]:
    """Turn the ``methods`` argument of :func:`run_evaluation` into checked specs.

    Names are checked against :func:`depthnormals.methods`; options must be JSON-ready.
    ``method_options`` maps a method name (options for every spec of that method) or a
    label (options for that spec, overriding) to extra options.
    """
    from ..registry import methods as registered

    if isinstance(methods, str):
        items: list[str | MethodSpec] = list(split_method_list(methods))
    elif isinstance(methods, Sequence):
        items = list(methods)
    else:
        raise TypeError(f"methods must be a string or a sequence of names; got "
                        f"{type(methods).__name__}")
    if not items:
        raise ValueError("methods is empty; pass at least one name from depthnormals.methods()")
    extra = dict(method_options or {})
    valid = registered()
    specs: list[MethodSpec] = []
    for item in items:
        spec = item if isinstance(item, MethodSpec) else parse_method_spec(item)
        if not isinstance(spec, MethodSpec):
            raise TypeError(f"a method must be a string or MethodSpec; got {type(item).__name__}")
        if spec.method not in valid:
            raise ValueError(f"unknown method {spec.method!r}; valid methods: {', '.join(valid)}")
        opts = dict(extra.get(spec.method, {}))
        opts.update(spec.options)
        if spec.label != spec.method:
            opts.update(extra.get(spec.label, {}))
        try:
            json.dumps(opts, sort_keys=True)
        except TypeError as exc:
            raise TypeError(f"options of {spec.label!r} must be JSON values: {exc}") from exc
        specs.append(MethodSpec(spec.label, spec.method, opts))
    labels = [s.label for s in specs]
    dupes = sorted({x for x in labels if labels.count(x) > 1})
    if dupes:
        raise ValueError(f"methods listed twice: {', '.join(dupes)}")
    unknown = [k for k in extra if k not in labels and k not in {s.method for s in specs}]
    if unknown:
        raise ValueError(f"method_options names {unknown}, which are not among the methods "
                         f"{labels}")
    return specs
