"""The VLM client against a real local chat-completions server replaying recorded answers."""

from __future__ import annotations

import base64
import json
import logging
import socket
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest
import trimesh
from PIL import Image

from pipelines.priors import VlmConfig, VlmGuess, ask_vlm, describe_object, estimate_prior, parse_answer, scan_image
from pipelines.priors.vlm import VlmError

GOOD = json.dumps({
    "material": "pla_printed", "density_kg_m3": 1240, "structure": "printed", "wall_thickness_mm": 1.2,
    "infill_fraction": 0.15, "mass_kg": 0.022, "friction_static": 0.4, "friction_kinetic": 0.3,
    "confidence": 0.7, "reasoning": "a matte printed cube with visible layer lines",
})


def _completion(content, refusal=None, finish_reason="stop") -> dict:
    message = {"role": "assistant", "content": content}
    if refusal is not None:
        message["refusal"] = refusal
    return {"id": "chatcmpl-1", "object": "chat.completion", "model": "replay",
            "choices": [{"index": 0, "message": message, "finish_reason": finish_reason}]}


# Recorded answers, chosen by the request's model name: (delay [s], HTTP status, body).
REPLIES = {
    "good": (0.0, 200, _completion(GOOD)),
    "fenced": (0.0, 200, _completion(f"Here is my estimate:\n```json\n{GOOD}\n```")),
    "malformed": (0.0, 200, _completion('{"material": "pla_printed", "density_kg_m3": 1240,')),
    "prose": (0.0, 200, _completion("It looks like a plastic cube, probably around 20 grams.")),
    "refusal": (0.0, 200, _completion(None, refusal="I'm sorry, I can't help with identifying this object.")),
    "filtered": (0.0, 200, _completion("", finish_reason="content_filter")),
    "slow": (1.5, 200, _completion(GOOD)),
    "overloaded": (0.0, 503, {"error": {"message": "model overloaded"}}),
    "unknown_model": (0.0, 404, {"error": {"message": "model 'unknown_model' not found"}}),
}


class _ReplayHandler(BaseHTTPRequestHandler):
    def do_POST(self):  # noqa: N802 (http.server's name)
        body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
        self.server.requests.append({"path": self.path, "headers": dict(self.headers), "body": body})
        delay, status, reply = REPLIES[body["model"]]
        time.sleep(delay)
        data = json.dumps(reply).encode()
        try:
            self.send_response(status)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data)
        except (BrokenPipeError, ConnectionResetError):
            pass  # the client gave up (timeout test)

    def log_message(self, *args):
        pass


@pytest.fixture(scope="module")
def server():
    """A chat-completions replay server on 127.0.0.1 (port chosen by the OS)."""
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), _ReplayHandler)
    httpd.daemon_threads = True
    httpd.requests = []
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield httpd
    httpd.shutdown()
    httpd.server_close()


@pytest.fixture(scope="module")
def image(tmp_path_factory) -> Path:
    """A small colour image of 'the object'."""
    path = tmp_path_factory.mktemp("img") / "frame_00001.png"
    Image.new("RGB", (32, 24), (200, 120, 40)).save(path)
    return path


@pytest.fixture(scope="module")
def cube():
    return trimesh.creation.box((0.04, 0.04, 0.04))


def _config(server, model: str, tmp_path: Path, **kw) -> VlmConfig:
    base = f"http://127.0.0.1:{server.server_address[1]}/v1"
    return VlmConfig(url=base, model=model, cache_dir=tmp_path / "vlm", timeout_s=0.5, retries=1, backoff_s=0.01,
                     **kw)


def test_answer_parsed_from_a_replayed_chat_completion(server, image, cube, tmp_path, monkeypatch):
    """The request carries the image as a data URL, the prompt's facts and the key; the answer is checked."""
    monkeypatch.setenv("TWIN_VLM_API_KEY", "sk-test")
    n = len(server.requests)
    guess = ask_vlm(_config(server, "good", tmp_path), image, describe_object(cube, "cube"))
    assert guess == VlmGuess(material="pla_printed", density_kg_m3=1240, mass_kg=0.022, structure="printed",
                             wall_thickness_m=pytest.approx(0.0012), infill_fraction=0.15, friction_static=0.4,
                             friction_kinetic=0.3, confidence=0.7, model="good",
                             reasoning="a matte printed cube with visible layer lines")
    (request,) = server.requests[n:]
    assert request["path"] == "/v1/chat/completions"
    assert request["headers"]["Authorization"] == "Bearer sk-test"
    text, picture = request["body"]["messages"][1]["content"]
    assert "40.0 x 40.0 x 40.0 mm" in text["text"] and "64.00 cm^3" in text["text"] and "pla_printed" in text["text"]
    header, data = picture["image_url"]["url"].split(",", 1)
    assert header == "data:image/png;base64" and base64.b64decode(data) == image.read_bytes()


def test_answer_cached_by_image_model_and_prompt(server, image, cube, tmp_path):
    """A second ask is answered from ~/.cache-like JSON files; another model asks the server again."""
    config = _config(server, "good", tmp_path)
    facts = describe_object(cube, "cube")
    n = len(server.requests)
    first = ask_vlm(config, image, facts)
    second = ask_vlm(config, image, facts)
    assert len(server.requests) == n + 1 and not first.cached and second.cached
    assert second.mass_kg == first.mass_kg
    (entry,) = (tmp_path / "vlm").glob("*.json")
    assert json.loads(entry.read_text())["model"] == "good"
    ask_vlm(_config(server, "fenced", tmp_path), image, facts)
    assert len(server.requests) == n + 2 and len(list((tmp_path / "vlm").glob("*.json"))) == 2


def test_fenced_answer_with_prose_is_read(server, image, cube, tmp_path):
    """JSON inside a ```json fence after a sentence is still the answer."""
    guess = ask_vlm(_config(server, "fenced", tmp_path), image, describe_object(cube))
    assert guess is not None and guess.material == "pla_printed"


@pytest.mark.parametrize("model, reason", [
    ("malformed", "malformed JSON"),
    ("prose", "no JSON object"),
    ("refusal", "refused"),
    ("filtered", "content filter"),
    ("slow", "no answer within 0.5 s"),
    ("overloaded", "HTTP 503"),
    ("unknown_model", "HTTP 404"),
])
def test_failures_degrade_to_the_offline_prior_with_a_warning(server, image, cube, tmp_path, caplog, model, reason):
    """Malformed, refused, filtered, slow and HTTP-error answers give None, a warning, and the offline prior."""
    with caplog.at_level(logging.WARNING, logger="pipelines.priors.vlm"):
        guess = ask_vlm(_config(server, model, tmp_path), image, describe_object(cube))
    assert guess is None
    assert any(reason in r.getMessage() and "offline prior" in r.getMessage() for r in caplog.records)
    assert not list((tmp_path / "vlm").glob("*.json"))  # failures are not cached
    prior = estimate_prior(cube, "pla_printed", guess)
    assert prior.inertial.mass == pytest.approx(estimate_prior(cube, "pla_printed").inertial.mass)
    assert prior.details["fusion"]["vlm"] is None


def test_retries_then_gives_up_on_a_server_error(server, image, cube, tmp_path):
    """A 503 is retried `retries` times before the client gives up."""
    n = len(server.requests)
    assert ask_vlm(_config(server, "overloaded", tmp_path), image, describe_object(cube)) is None
    assert len(server.requests) == n + 2


def test_deadline_bounds_the_time_spent_on_a_slow_server(server, image, cube, tmp_path, caplog):
    """With a 0.8 s deadline a server answering in 1.5 s costs at most two attempts and under a second."""
    config = _config(server, "slow", tmp_path, deadline_s=0.8)
    config = VlmConfig(**{**config.__dict__, "retries": 5})
    n = len(server.requests)
    t0 = time.perf_counter()
    with caplog.at_level(logging.WARNING, logger="pipelines.priors.vlm"):
        assert ask_vlm(config, image, describe_object(cube)) is None
    assert time.perf_counter() - t0 < 1.2 and len(server.requests) - n <= 2
    assert "no answer within" in caplog.text


def test_absent_server_and_missing_image_degrade_with_a_warning(image, cube, tmp_path, caplog):
    """No server listening, or no image (a mesh source), gives None and a warning naming the cause."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # closed again: nothing listens there
    config = VlmConfig(url=f"http://127.0.0.1:{port}/v1", model="m", cache_dir=None, timeout_s=0.5, retries=1,
                       backoff_s=0.01)
    with caplog.at_level(logging.WARNING, logger="pipelines.priors.vlm"):
        assert ask_vlm(config, image, describe_object(cube)) is None
        assert ask_vlm(config, None, describe_object(cube)) is None
        assert ask_vlm(config, tmp_path / "missing.png", describe_object(cube)) is None
    messages = " | ".join(r.getMessage() for r in caplog.records)
    assert "cannot reach the server" in messages and "no colour image" in messages and "missing.png" in messages


@pytest.mark.parametrize("content, expect", [
    ('{"material": "oak", "density_kg_m3": "700", "confidence": 80}', {"material": "oak", "density_kg_m3": 700.0,
                                                                        "confidence": 0.8}),
    ('{"mass_kg": 0.02, "infill_fraction": 20, "structure": "3D printed"}', {"infill_fraction": 0.2,
                                                                            "structure": "printed"}),
    ('{"mass_kg": 0.02, "structure": "Hollow shell", "wall_thickness_mm": 2}', {"structure": "hollow",
                                                                                "wall_thickness_m": 0.002}),
    ('{"material": "steel", "density_kg_m3": -5, "friction_static": 9}', {"density_kg_m3": None,
                                                                          "friction_static": None}),
])
def test_parse_answer_checks_each_field(content, expect):
    """Numbers as strings and percentages are read; values outside physical ranges are dropped."""
    guess = parse_answer(content)
    for key, value in expect.items():
        assert getattr(guess, key) == (pytest.approx(value) if isinstance(value, float) else value)


@pytest.mark.parametrize("content", ["[1, 2]", '{"confidence": 0.9}', "sorry", '{"material": '])
def test_parse_answer_refuses_unusable_answers(content):
    """No object, or one without material, density or mass, is a VlmError."""
    with pytest.raises(VlmError):
        parse_answer(content)


def test_scan_image_picks_the_middle_frame(tmp_path, cube):
    """A nerfstudio scan gives its middle colour frame; a mesh file gives none."""
    (tmp_path / "images").mkdir()
    frames = []
    for k in range(5):
        Image.new("RGB", (4, 4)).save(tmp_path / "images" / f"frame_{k:05d}.png")
        frames.append({"file_path": f"images/frame_{k:05d}.png"})
    (tmp_path / "transforms.json").write_text(json.dumps({"frames": frames}))
    assert scan_image(tmp_path) == tmp_path / "images" / "frame_00002.png"
    mesh_path = tmp_path / "cube.stl"
    cube.export(mesh_path)
    assert scan_image(mesh_path) is None


def test_build_goes_on_when_the_vlm_refuses(server, tmp_path):
    """`twin build --vlm` against a refusing model writes the asset from the offline prior."""
    from twin.build import BuildConfig, build

    sample = Path(__file__).resolve().parents[3] / "samples" / "cube"
    url = f"http://127.0.0.1:{server.server_address[1]}/v1"
    lines = []
    out = build(BuildConfig(source=sample / "scan", logs=(sample / "trial.mcap",), output=tmp_path / "out",
                            method="ls", vlm=url, vlm_model="refusal"), log=lines.append)
    prior = json.loads((out / "asset.json").read_text())["provenance"]["prior"]
    assert prior["material"] == "pla_printed" and prior["fusion"]["vlm"] is None
    assert "VLM: no usable answer; using the offline prior" in lines
