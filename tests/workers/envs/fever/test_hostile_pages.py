"""Hostile Wikipedia answers stay bounded (issue 35 items 7-9): one deadline per answer, retries
included; a cap on the decoded size with nothing stored past it; redirects only within the
configured origin, each hop rate-limited. Real loopback servers (:mod:`.hostile`)."""

from __future__ import annotations

import gzip
import zlib

import pytest

from schemas.records import WikiPageRecord, WikiRequestRecord
from tests.workers.envs.fever import hostile
from tests.workers.envs.fever.hostile import DEADLINE_S, PAGE, SLACK_S, MiB
from workers.envs.fever import BENCHMARK
from workers.envs.fever.fetch import TooLarge, _Decoder


@pytest.mark.parametrize("attack", [hostile.attack_drip, hostile.attack_drip_headers])
def test_a_dripping_server_is_cut_at_one_deadline_for_the_whole_answer(attack):
    out = attack()
    assert out.kind == "timeout", out.detail()
    assert out.message.endswith(f"did not arrive within its {DEADLINE_S:g} s deadline")
    assert DEADLINE_S - 0.1 <= out.elapsed_s <= DEADLINE_S + SLACK_S, out.detail()
    assert out.rows == []


def test_retries_stop_where_the_next_one_would_pass_the_deadline():
    out = hostile.attack_slow_retries()  # 500 after 1.5 s each time; four tries and their waits: 13 s
    assert out.kind == "unavailable", out.detail()  # the site failing: a resume tries it again
    assert out.message.endswith(f"(HTTP 500; the next try would pass the {DEADLINE_S:g} s deadline, 1 attempt(s))")
    assert out.elapsed_s <= DEADLINE_S + SLACK_S and out.hits == {"wiki": 1}


def test_a_gzip_bomb_is_refused_with_memory_bounded_and_nothing_stored():
    out = hostile.attack_gzip_bomb(256 * MiB)
    assert out.kind == "too_large", out.detail()
    assert out.message.endswith(f"refused: the decoded answer passes {5 * MiB} bytes")
    assert out.rows == [] and out.hits == {"wiki": 1}  # refused, not retried
    assert out.peak_bytes < 16 * MiB, out.detail()  # the cap, one chunk and the decoder's window


@pytest.mark.parametrize("with_length", [True, False])
def test_a_big_plain_page_is_refused_with_memory_bounded_and_nothing_stored(with_length):
    out = hostile.attack_big_page(54 * MiB, with_length=with_length)
    assert out.kind == "too_large", out.detail()
    said = f"the answer says it is {54 * MiB} bytes" if with_length else "the answer as sent passes"
    assert said in out.message
    assert out.rows == [] and out.hits == {"wiki": 1}
    assert out.peak_bytes < 16 * MiB, out.detail()


def test_an_ordinary_gzip_page_is_served_decoded():
    out = hostile.attack_small_gzip_page()
    assert out.kind is None
    page, request = out.rows
    assert isinstance(page, WikiPageRecord) and page.body == PAGE and page.size == len(PAGE)
    assert isinstance(request, WikiRequestRecord) and (request.status, request.encoding) == (200, "UTF-8")


def test_the_size_cap_and_the_deadline_are_fever_options(claims_dir):
    make = BENCHMARK.make
    env = make("fever/1001", data_dir=str(claims_dir), wikipedia_max_page_bytes=1000, wikipedia_deadline_s=5)
    policy = env.source.policy  # type: ignore[attr-defined]
    assert (policy.max_page_bytes, policy.deadline_s) == (1000, 5.0)
    assert (make("fever/1001", data_dir=str(claims_dir)).source.policy.max_page_bytes) == 5 * MiB  # type: ignore[attr-defined]
    with pytest.raises(
        ValueError, match=r"^wikipedia_max_page_bytes must be a positive number of bytes \(default 5242880\), got 0$"
    ):
        make("fever/1001", data_dir=str(claims_dir), wikipedia_max_page_bytes=0)
    with pytest.raises(ValueError, match=r"^wikipedia_deadline_s must be a number of seconds above 0 \(default 60\), got -1$"):
        make("fever/1001", data_dir=str(claims_dir), wikipedia_deadline_s=-1)


@pytest.mark.parametrize(
    ("attack", "target"),
    [
        (hostile.attack_cross_host, "http://127.0.0.2:{port}/wiki/Elsewhere"),
        (hostile.attack_cross_port, None),
        (hostile.attack_scheme_change, "https://127.0.0.1:{port}/wiki/Elsewhere"),
    ],
)
def test_a_redirect_off_the_configured_origin_is_refused_and_never_reached(attack, target):
    out = attack()
    assert out.kind == "redirect", out.detail()
    assert " redirects to " in out.message and "outside the configured Wikipedia http://127.0.0.1:" in out.message
    assert out.hits.get("other", 0) == 0 and out.hits["wiki"] == 1
    assert out.rows == [] and len(out.acquired) == 1  # only the configured host was asked for


def test_too_many_same_host_redirects_are_refused():
    out = hostile.attack_redirect_loop(max_redirects=5)
    assert out.kind == "redirect" and out.message.endswith("redirects more than 5 times"), out.detail()
    assert out.hits == {"wiki": 6} and out.rows == []
    assert len(out.acquired) == 6  # every hop booked with the rate limit


def test_a_same_host_redirect_is_served_and_each_hop_is_rate_limited():
    out = hostile.attack_same_host_redirect()
    assert out.kind is None
    assert out.hits == {"wiki": 2} and len(set(out.acquired)) == 1 and len(out.acquired) == 2
    request = out.rows[-1]
    assert request.final_url.endswith("/wiki/Article") and request.url.endswith("search=Hop")
    # one token at 2/s and a clock that stands still: the second hop waits for its own slot
    assert hostile.same_host_hops_wait(2.0) == [0.5]


def test_the_proxy_the_environment_names_is_used_as_requests_used_it(monkeypatch):
    """http.client does not read the proxy variables; the fetch does (an http proxy gets the absolute URL)."""
    with hostile.servers(proxy=({}, "127.0.0.1", 0)) as s:
        monkeypatch.setenv("http_proxy", s["proxy"].base_url)
        monkeypatch.setenv("no_proxy", "")
        source = hostile.LiveSource(None, limiter=hostile.RecordingLimiter(), policy=hostile.RetryPolicy())
        assert source.fetch("http://wiki.invalid/w/index.php?search=Anything") == PAGE.decode()
        assert s["proxy"].hits == ["http://wiki.invalid:80/w/index.php?search=Anything"]


@pytest.mark.parametrize(
    ("encoding", "encode"),
    [
        ("gzip", lambda b: gzip.compress(b[:10]) + gzip.compress(b[10:])),  # two members
        ("deflate", zlib.compress),  # zlib-wrapped
        ("deflate", lambda b: zlib.compress(b, wbits=-zlib.MAX_WBITS)),  # raw, as some servers send it
        ("identity", lambda b: b),
    ],
)
def test_bodies_are_decoded_as_requests_decoded_them(encoding, encode):
    out = bytearray()
    decoder = _Decoder(encoding, 1000, out)
    data = encode(PAGE)
    for i in range(0, len(data), 7):  # chunk by chunk, as they come off the socket
        decoder.feed(data[i : i + 7])
    assert bytes(out) == PAGE
    with pytest.raises(TooLarge, match=f"^the decoded answer passes {len(PAGE) - 1} bytes$"):
        _Decoder(encoding, len(PAGE) - 1, bytearray()).feed(data)
