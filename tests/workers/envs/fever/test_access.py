"""Wikipedia access: User-Agent, retries on 429/5xx with Retry-After, timeouts, the rate limit, recorded pages and snapshots."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.workers.envs.fever.test_observations import ARTICLE_OBS, SIMILAR
from workers.envs.fever import WikiError
from workers.envs.fever.pages import PageRecord, Snapshot, SnapshotError, sha256_hex, write_pages
from workers.envs.fever.ratelimit import TokenBucket
from workers.envs.fever.wiki import LiveSource, RetryPolicy, retry_after_seconds, search_url, user_agent


def live(standin_store=None, **policy):
    waits: list[float] = []
    source = LiveSource(standin_store, limiter=TokenBucket(1000.0, 1000), policy=RetryPolicy(**policy), sleep=waits.append)
    return source, waits


def test_search_url_is_prepared_as_the_release_prepares_it():
    base = "https://en.wikipedia.org"
    assert search_url(base + "/", "Nikolaj Coster-Waldau") == f"{base}/w/index.php?search=Nikolaj+Coster-Waldau"
    assert search_url(base, "AT&T") == f"{base}/w/index.php?search=AT&T"
    assert search_url(base, "C#") == f"{base}/w/index.php?search=C"
    assert search_url(base, "Beyoncé") == f"{base}/w/index.php?search=Beyonc%C3%A9"
    assert search_url(base, "[Mercury]") == f"{base}/w/index.php?search=%5BMercury%5D"
    assert search_url(base, "100%") == f"{base}/w/index.php?search=100%25"


def test_requests_carry_an_honest_user_agent(make, standin):
    env = make(1001)
    env.reset()
    env.step("search[Nikolaj]")
    assert standin.user_agents == [user_agent()]
    assert user_agent().startswith("recap-eval/") and "https://" in user_agent()


def test_429_is_retried_after_the_wait_the_server_asks_for(standin, store):
    source, waits = live(store)
    html = source.fetch(search_url(standin.base_url, "Busy"))
    assert "Nikolaj William Coster-Waldau" in html
    assert waits == [7.0]
    assert standin.requests == ["/w/index.php?search=Busy"] * 2
    assert [r.status for r in store.records] == [200]  # only the answer that was read is kept


def test_server_errors_are_retried_a_bounded_number_of_times_then_an_environment_error(standin, store):
    source, waits = live(store, attempts=3, backoff_s=0.5)
    with pytest.raises(WikiError, match=r"search=Broken could not be fetched \(HTTP 500, 3 attempt\(s\)\)") as info:
        source.fetch(search_url(standin.base_url, "Broken"))
    assert (info.value.kind, info.value.end_reason) == ("unavailable", "wiki_error")
    assert waits == [0.5, 1.0]
    assert len(standin.requests) == 3 and store.records == []


def test_a_refusal_is_not_retried(standin):
    source, waits = live(attempts=4)
    with pytest.raises(WikiError, match=r"\(HTTP 403, 1 attempt\(s\)\)"):
        source.fetch(search_url(standin.base_url, "Gone"))
    assert waits == [] and len(standin.requests) == 1


def test_a_slow_answer_times_out_and_is_an_environment_error(standin):
    source, waits = live(attempts=2, backoff_s=0.25, timeout_s=0.2)
    with pytest.raises(WikiError, match=r"could not be fetched \(TimeoutError: timed out, 2 attempt\(s\)\)"):
        source.fetch(search_url(standin.base_url, "Slow"))
    assert waits == [0.25]


def test_an_episode_stops_with_the_error_and_no_observation(make, standin):
    env = make(1001)
    env.reset()
    with pytest.raises(WikiError, match="search=Gone could not be fetched"):
        env.step("search[Gone]")
    assert env.obs == "Claim: Nikolaj Coster-Waldau worked with the Fox Broadcasting Company." and env.steps_taken == 0


def test_retry_after_reads_seconds_and_dates():
    assert retry_after_seconds("12") == 12.0
    assert retry_after_seconds(None) is None and retry_after_seconds("soon") is None
    assert retry_after_seconds("Wed, 21 Oct 2015 07:28:10 GMT", now=1445412480.0) == 10.0


def test_token_bucket_spaces_requests_per_host():
    now = [0.0]
    waits: list[float] = []

    def sleep(s: float) -> None:
        waits.append(s)

    bucket = TokenBucket(2.0, 2, clock=lambda: now[0], sleep=sleep)
    for _ in range(4):
        bucket.acquire("en.wikipedia.org")
    bucket.acquire("other.example")
    assert waits == [0.5, 1.0]  # burst of 2, then one every 0.5 s (reserved in order); another host waits for nothing
    now[0] = 10.0
    bucket.acquire("en.wikipedia.org")
    assert waits == [0.5, 1.0]
    with pytest.raises(ValueError, match="rate must be > 0"):
        TokenBucket(0)


def test_a_snapshot_replays_a_run_offline_with_identical_observations(make, standin, store, tmp_path: Path):
    actions = [
        "search[Nikolaj Coster-Waldau]",
        "search[Nikolaj]",
        "search[Mercury]",
        "lookup[Copenhagen]",
        "search[Coster-Waldau]",
    ]
    env = make(1001)
    env.reset()
    recorded = [env.step(a).observation for a in actions]
    assert recorded[0] == ARTICLE_OBS and recorded[1] == SIMILAR
    write_pages(store.records, tmp_path / "run" / "wiki_pages.parquet")
    base, served = standin.base_url, len(standin.requests)
    standin.stop()
    replay = make(1001, wikipedia=f"snapshot:{tmp_path / 'run'}", wikipedia_url=base)
    replay.reset()
    assert [replay.step(a).observation for a in actions] == recorded
    assert len(standin.requests) == served  # not one request in snapshot mode
    with pytest.raises(WikiError, match=r"holds no answer for .*search=Paris") as info:
        replay.step("search[Paris]")
    assert info.value.kind == "snapshot_miss"


def test_a_snapshot_checks_its_bodies_and_its_folder(tmp_path: Path):
    with pytest.raises(SnapshotError, match="holds no wiki_pages.parquet nor wiki_pages/\\*.parquet"):
        Snapshot(tmp_path)
    good = PageRecord(
        "http://x/w/index.php?search=A",
        sha256_hex(b"<p>a b c</p>"),
        200,
        "2024-01-01T00:00:00.000+00:00",
        b"<p>a b c</p>",
        "utf-8",
    )
    bad = PageRecord(
        "http://x/w/index.php?search=B", sha256_hex(b"other"), 200, "2024-01-01T00:00:00.000+00:00", b"<p>x y z</p>", "utf-8"
    )
    write_pages([good], tmp_path / "wiki_pages" / "part-0.parquet")
    snap = Snapshot(tmp_path)
    assert len(snap) == 1 and snap.get(good.url) == good
    write_pages([bad], tmp_path / "wiki_pages" / "part-1.parquet")
    with pytest.raises(SnapshotError, match="the body of 'http://x/w/index.php\\?search=B' does not match its sha256"):
        Snapshot(tmp_path)


def test_bad_options_are_refused(make):
    with pytest.raises(ValueError, match="wikipedia_url must be an http\\(s\\) base URL"):
        make(1001, wikipedia_url="en.wikipedia.org")
    with pytest.raises(ValueError, match="wikipedia must be 'live' or 'snapshot:DIR'"):
        make(1001, wikipedia="offline")
    with pytest.raises(ValueError, match="unknown FEVER option\\(s\\) colour"):
        make(1001, colour="red")
    with pytest.raises(ValueError, match="max_steps must be a positive integer"):
        make(1001, max_steps=0)
