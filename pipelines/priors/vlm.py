"""A VLM's guess at an object's material: OpenAI-compatible chat completions with one colour image.

Works with any server speaking `POST {base}/chat/completions` with image input
(vLLM, Ollama, LM Studio, hosted services). The prompt gives the scan's
measured size and volume and the library's material names, and asks for one
JSON object: material, density, solid / hollow / printed, wall thickness,
infill, mass, static and kinetic friction, confidence. Answers are cached as
JSON files keyed by the image's hash, the model and the prompt.

`ask_vlm` never raises: a timeout, connection failure, HTTP error, refusal or
malformed answer is logged as a warning and gives None, so the build goes on
with the offline prior.
"""

from __future__ import annotations

import base64
import hashlib
import io
import json
import logging
import os
import socket
import time
import urllib.error
import urllib.parse
import urllib.request
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

logger = logging.getLogger(__name__)

API_KEY_ENV = "TWIN_VLM_API_KEY"
PROMPT_VERSION = "twin-vlm-1"
IMAGE_SUFFIXES = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".webp": "image/webp"}


class VlmError(RuntimeError):
    """A VLM request or answer that cannot be used; the message says why."""


@dataclass(frozen=True)
class VlmConfig:
    """Where and how to ask the VLM."""

    url: str
    """Base URL of an OpenAI-compatible server (e.g. http://127.0.0.1:8000/v1), or its /chat/completions URL."""
    model: str
    """Model name as the server knows it."""
    api_key_env: str = API_KEY_ENV
    """Environment variable holding the API key (sent as a Bearer token when set)."""
    timeout_s: float = 60.0
    """Per attempt: connecting and each read [s]."""
    retries: int = 2
    """Further attempts after a timeout, connection failure, HTTP 429 or 5xx."""
    deadline_s: float = 120.0
    """No attempt starts after this many seconds, and none runs past it [s]."""
    backoff_s: float = 1.0
    """Wait before the first retry [s]; doubles each time."""
    cache_dir: Path | None = Path.home() / ".cache" / "twin" / "vlm"
    """Answers cached as JSON here; None: no cache."""
    max_image_px: int = 1024
    """Longer image side sent [pixels]; larger images are downscaled (JPEG)."""
    max_tokens: int = 600
    temperature: float = 0.0

    def endpoint(self) -> str:
        url = self.url.rstrip("/")
        return url if url.endswith("/chat/completions") else url + "/chat/completions"


@dataclass(frozen=True)
class ObjectFacts:
    """What the prompt tells the VLM about the object: name, size [m] and volume [m^3] from the scan."""

    extents_m: tuple[float, float, float]
    volume_m3: float
    name: str | None = None
    material_hint: str | None = None


def describe_object(mesh_object, name: str | None = None, material_hint: str | None = None) -> ObjectFacts:
    """The facts of a watertight mesh (metres): bounding-box size and enclosed volume."""
    extents = tuple(float(x) for x in mesh_object.extents)
    return ObjectFacts(extents, float(abs(mesh_object.volume)), name, material_hint)


@dataclass(frozen=True)
class VlmGuess:
    """A VLM's answer, checked; fields it gave no usable value for are None.

    density_kg_m3: of the material itself [kg/m^3]; mass_kg: the whole object [kg];
    structure: "solid", "hollow" or "printed"; wall_thickness_m [m]; infill_fraction
    (0..1); friction_static, friction_kinetic (unitless); confidence (0..1).
    """

    material: str | None = None
    density_kg_m3: float | None = None
    mass_kg: float | None = None
    structure: Literal["solid", "hollow", "printed"] | None = None
    wall_thickness_m: float | None = None
    infill_fraction: float | None = None
    friction_static: float | None = None
    friction_kinetic: float | None = None
    confidence: float = 0.5
    model: str = ""
    reasoning: str = ""
    cached: bool = False

    def to_json(self) -> dict:
        return asdict(self)


def build_prompt(facts: ObjectFacts, material_names: tuple[str, ...]) -> tuple[str, str]:
    """(system, user) messages: the object's measured facts and the JSON answer wanted."""
    system = ("You are an expert in materials and mechanics. A robot will simulate the object in the image and "
              "needs its physical properties. Reply with a single JSON object and nothing else.")
    dx, dy, dz = (1000 * e for e in facts.extents_m)
    lines = [f"Object: {facts.name or 'unnamed'}."]
    if facts.material_hint:
        lines.append(f"The user says it is made of: {facts.material_hint}.")
    lines += [
        f"Measured from its 3D scan: bounding box {dx:.1f} x {dy:.1f} x {dz:.1f} mm, "
        f"enclosed volume {facts.volume_m3 * 1e6:.2f} cm^3.",
        "Look at the image and estimate:",
        f"- material: one of [{', '.join(material_names)}] if one fits, else a short name",
        "- density_kg_m3: density of that material itself, kg/m^3",
        '- structure: "solid", "hollow" (a shell with walls) or "printed" (3D-printed: walls plus sparse infill)',
        "- wall_thickness_mm: wall thickness if hollow or printed, else null",
        "- infill_fraction: infill volume fraction 0-1 if printed, else null",
        "- mass_kg: mass of the whole object in kg, consistent with its volume and structure",
        "- friction_static, friction_kinetic: Coulomb friction coefficients against a wooden table",
        "- confidence: 0-1, how sure you are of the material and the mass",
        'Answer with JSON only: {"material": "...", "density_kg_m3": 0, "structure": "...", '
        '"wall_thickness_mm": null, "infill_fraction": null, "mass_kg": 0, "friction_static": 0, '
        '"friction_kinetic": 0, "confidence": 0, "reasoning": "one sentence"}',
    ]
    return system, "\n".join(lines)


def ask_vlm(config: VlmConfig, image_path: Path | None, facts: ObjectFacts) -> VlmGuess | None:
    """The VLM's guess for the object in `image_path`, or None (with a warning) on any failure."""
    try:
        return _ask(config, image_path, facts)
    except VlmError as exc:
        logger.warning("VLM %s at %s: %s; using the offline prior", config.model, config.url, exc)
    except Exception as exc:  # never fail a build over the VLM
        logger.warning("VLM %s at %s failed unexpectedly (%s: %s); using the offline prior",
                       config.model, config.url, type(exc).__name__, exc)
    return None


def _ask(config: VlmConfig, image_path: Path | None, facts: ObjectFacts) -> VlmGuess:
    from assets.materials import material_names

    if image_path is None:
        raise VlmError("no colour image of the object (a mesh source has none)")
    try:
        image_bytes = Path(image_path).read_bytes()
    except OSError as exc:
        raise VlmError(f"{image_path}: cannot read the image ({exc})") from exc
    system, user = build_prompt(facts, material_names())
    image_sha256 = hashlib.sha256(image_bytes).hexdigest()
    key = hashlib.sha256(json.dumps({
        "version": PROMPT_VERSION, "model": config.model, "system": system, "user": user,
        "image_sha256": image_sha256, "max_image_px": config.max_image_px,
    }, sort_keys=True).encode()).hexdigest()
    cached = _read_cache(config, key)
    if cached is not None:
        try:
            guess = parse_answer(cached, config.model)
            return VlmGuess(**{**guess.to_json(), "cached": True})
        except VlmError:
            pass  # a stale or damaged entry: ask again
    mime, data = _encode_image(image_bytes, Path(image_path), config.max_image_px)
    body = {
        "model": config.model,
        "messages": [
            {"role": "system", "content": system},
            {"role": "user", "content": [
                {"type": "text", "text": user},
                {"type": "image_url", "image_url": {"url": f"data:{mime};base64,{base64.b64encode(data).decode()}"}},
            ]},
        ],
        "temperature": config.temperature,
        "max_tokens": config.max_tokens,
    }
    reply = _post(config, body)
    content = _message_content(reply)
    guess = parse_answer(content, config.model)
    _write_cache(config, key, content, {"served_model": reply.get("model"), "image_sha256": image_sha256,
                                        "image": str(image_path)})
    return guess


def _post(config: VlmConfig, body: dict) -> dict:
    """POST with retries on timeouts, connection failures, 429 and 5xx; the decoded JSON reply."""
    url = config.endpoint()
    headers = {"Content-Type": "application/json", "Accept": "application/json"}
    key = os.environ.get(config.api_key_env)
    if key:
        headers["Authorization"] = f"Bearer {key}"
    host = urllib.parse.urlsplit(url).hostname or ""
    # Loopback servers are reached directly even where a proxy is configured.
    handlers = [urllib.request.ProxyHandler({})] if host in ("127.0.0.1", "localhost", "::1") else []
    opener = urllib.request.build_opener(*handlers)
    data = json.dumps(body).encode()
    last = "no attempt"
    t_end = time.monotonic() + config.deadline_s
    attempts = 0
    for attempt in range(config.retries + 1):
        if attempt:
            time.sleep(min(config.backoff_s * 2 ** (attempt - 1), max(t_end - time.monotonic(), 0.0)))
        timeout = min(config.timeout_s, t_end - time.monotonic())
        if timeout <= 0:
            break
        attempts += 1
        try:
            request = urllib.request.Request(url, data=data, headers=headers, method="POST")
            with opener.open(request, timeout=timeout) as response:
                raw = response.read()
        except urllib.error.HTTPError as exc:
            detail = exc.read()[:200].decode(errors="replace") if exc.fp else ""
            last = f"HTTP {exc.code} {exc.reason} {detail}".strip()
            if exc.code == 429 or exc.code >= 500:
                continue
            raise VlmError(last) from exc
        except (TimeoutError, socket.timeout) as exc:
            last = f"no answer within {timeout:.3g} s ({exc})"
            continue
        except (urllib.error.URLError, ConnectionError, OSError) as exc:
            reason = getattr(exc, "reason", exc)
            last = (f"no answer within {timeout:.3g} s" if isinstance(reason, (TimeoutError, socket.timeout))
                    else f"cannot reach the server ({reason})")
            continue
        try:
            reply = json.loads(raw)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise VlmError(f"the reply is not JSON ({exc})") from exc
        if not isinstance(reply, dict):
            raise VlmError("the reply is not a JSON object")
        return reply
    raise VlmError(f"{last} after {attempts} attempt(s)")


def _message_content(reply: dict) -> str:
    """The assistant's text, or VlmError for a refusal, a filtered or an empty answer."""
    if "error" in reply:
        raise VlmError(f"the server answered an error: {str(reply['error'])[:200]}")
    try:
        choice = reply["choices"][0]
        message = choice["message"]
    except (KeyError, IndexError, TypeError) as exc:
        raise VlmError("the reply has no choices[0].message") from exc
    if message.get("refusal"):
        raise VlmError(f"the model refused: {str(message['refusal'])[:200]}")
    if choice.get("finish_reason") == "content_filter":
        raise VlmError("the answer was withheld by the server's content filter")
    content = message.get("content")
    if isinstance(content, list):  # content parts
        content = "".join(p.get("text", "") for p in content if isinstance(p, dict))
    if not isinstance(content, str) or not content.strip():
        raise VlmError("the answer is empty")
    return content


def parse_answer(content: str, model: str = "") -> VlmGuess:
    """The JSON object in an answer (code fences and surrounding prose allowed), checked field by field.

    Values outside physical ranges are dropped with a warning; VlmError when there
    is no JSON object or it gives none of material, density and mass.
    """
    text = content.strip()
    if text.startswith("```"):
        text = text.strip("`")
        text = text[text.find("\n") + 1:] if "\n" in text else text
    start, end = text.find("{"), text.rfind("}")
    if start < 0:
        raise VlmError(f"no JSON object in the answer: {content.strip()[:120]!r}")
    if end <= start:
        raise VlmError(f"malformed JSON in the answer (unterminated object): {content.strip()[:120]!r}")
    try:
        doc = json.loads(text[start:end + 1])
    except json.JSONDecodeError as exc:
        raise VlmError(f"malformed JSON in the answer ({exc}): {content.strip()[:120]!r}") from exc
    if not isinstance(doc, dict):
        raise VlmError("the answer's JSON is not an object")

    def number(key: str, lo: float, hi: float, scale: float = 1.0, percent: bool = False) -> float | None:
        value = doc.get(key)
        if value is None or value == "":
            return None
        try:
            x = float(value)
        except (TypeError, ValueError):
            logger.warning("VLM answer: %s=%r is not a number; ignored", key, value)
            return None
        if percent and 1.0 < x <= 100.0:
            x /= 100.0
        x *= scale
        if not (lo <= x <= hi):
            logger.warning("VLM answer: %s=%r outside [%g, %g]; ignored", key, value, lo / scale, hi / scale)
            return None
        return x

    material = doc.get("material")
    material = str(material).strip() if isinstance(material, str) and material.strip() else None
    structure = str(doc.get("structure") or "").strip().lower()
    structure = ("printed" if "print" in structure or "infill" in structure else
                 "hollow" if "hollow" in structure or "shell" in structure else
                 "solid" if "solid" in structure else None)
    confidence = number("confidence", 0.0, 1.0, percent=True)
    guess = VlmGuess(
        material=material,
        density_kg_m3=number("density_kg_m3", 1.0, 25000.0),
        mass_kg=number("mass_kg", 1e-5, 1e4),
        structure=structure,
        wall_thickness_m=number("wall_thickness_mm", 5e-5, 0.1, scale=1e-3),
        infill_fraction=number("infill_fraction", 0.0, 1.0, percent=True),
        friction_static=number("friction_static", 0.01, 3.0),
        friction_kinetic=number("friction_kinetic", 0.01, 3.0),
        confidence=0.5 if confidence is None else confidence,
        model=model,
        reasoning=str(doc.get("reasoning") or "")[:500],
    )
    if guess.material is None and guess.density_kg_m3 is None and guess.mass_kg is None:
        raise VlmError(f"the answer gives no material, density or mass: {content.strip()[:120]!r}")
    return guess


def _encode_image(data: bytes, path: Path, max_px: int) -> tuple[str, bytes]:
    """(MIME type, bytes) to send: the file as is when small and of a common type, else a JPEG at most max_px."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as img:
            if max(img.size) <= max_px and path.suffix.lower() in IMAGE_SUFFIXES:
                return IMAGE_SUFFIXES[path.suffix.lower()], data
            img = img.convert("RGB")
            img.thumbnail((max_px, max_px))
            out = io.BytesIO()
            img.save(out, format="JPEG", quality=90)
            return "image/jpeg", out.getvalue()
    except (UnidentifiedImageError, OSError) as exc:
        raise VlmError(f"{path}: not an image ({exc})") from exc


def _read_cache(config: VlmConfig, key: str) -> str | None:
    if config.cache_dir is None:
        return None
    path = Path(config.cache_dir) / f"{key}.json"
    try:
        return json.loads(path.read_text())["content"]
    except (OSError, json.JSONDecodeError, KeyError, TypeError):
        return None


def _write_cache(config: VlmConfig, key: str, content: str, about: dict) -> None:
    if config.cache_dir is None:
        return
    path = Path(config.cache_dir) / f"{key}.json"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps({"model": config.model, "url": config.url, "prompt_version": PROMPT_VERSION,
                                   **about, "content": content}, indent=1))
        tmp.replace(path)
    except OSError as exc:
        logger.warning("VLM answer not cached at %s (%s)", path, exc)


def scan_image(source: Path) -> Path | None:
    """A colour image of the object from a scan directory (the middle frame), or None for a mesh source."""
    source = Path(source)
    if not source.is_dir():
        return None
    transforms = source / "transforms.json"
    if transforms.is_file():
        try:
            frames = json.loads(transforms.read_text()).get("frames", [])
            paths = [source / f["file_path"] for f in frames if isinstance(f, dict) and "file_path" in f]
        except (OSError, json.JSONDecodeError, AttributeError):
            paths = []
        paths = [p for p in paths if p.is_file()]
        if paths:
            return paths[len(paths) // 2]
    for pattern in ("*.color.*", "images/*", "rgb/*", "color/*"):
        paths = sorted(p for p in source.glob(pattern) if p.suffix.lower() in IMAGE_SUFFIXES)
        if paths:
            return paths[len(paths) // 2]
    return None
