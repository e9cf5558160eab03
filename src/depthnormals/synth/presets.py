"""Named settings of :func:`depthnormals.synth.generate`: ``depthnormals synth --preset NAME``.

``ssn``: the scale of the SSN benchmark of the 3F2N+ paper (Fan et al., "Three-filters-to-normal+",
2024): 10 indoor + 10 outdoor scenes x 500 views = 10,000 views at the Kinect v2 size
(512 x 424), clean and one variant per model of :data:`SSN_NOISE_MODELS`, stored compactly
(format version 2), from the ``"mixed"`` scene set: every asset-mesh recipe first (7 indoor,
5 outdoor), then procedural ones (:func:`depthnormals.synth.catalog.scene_names`). Options given
explicitly override the preset's values.

Examples
--------
>>> p = preset("ssn")
>>> p["indoor"] + p["outdoor"], p["views"], p["size"], p["storage"]
(20, 500, (424, 512), 'compact')
"""

from __future__ import annotations

from typing import Any

from ..render import KINECT_V2, KINECT_V2_SIZE

__all__ = ["PRESETS", "SSN_NOISE_MODELS", "preset"]

#: Noise models of the ``ssn`` preset, one noisy variant each, in this order. The one place to
#: extend when a model lands in :data:`depthnormals.synth.noise.MODELS`.
SSN_NOISE_MODELS: tuple[str, ...] = ("kinect_v2", "gaussian", "realsense_d4xx", "tof")

#: preset name -> keyword arguments of :func:`depthnormals.synth.generate`.
PRESETS: dict[str, dict[str, Any]] = {
    "ssn": {"indoor": 10, "outdoor": 10, "views": 500, "noise": SSN_NOISE_MODELS, "K": KINECT_V2,
            "size": KINECT_V2_SIZE, "storage": "compact", "scenes": "mixed"},
}


def preset(name: str) -> dict[str, Any]:
    """Keyword arguments of :func:`depthnormals.synth.generate` for preset ``name`` (a copy).

    Parameters
    ----------
    name : str
        One of :data:`PRESETS` (``"ssn"``).

    Returns
    -------
    dict
        ``indoor``, ``outdoor``, ``views``, ``noise``, ``K``, ``size``, ``storage``, ``scenes``; pass it on
        as ``generate(out, **preset("ssn"))``, overriding entries as needed.
    """
    if name not in PRESETS:
        raise ValueError(f"unknown synth preset {name!r}; valid: {', '.join(PRESETS)}")
    return dict(PRESETS[name])
