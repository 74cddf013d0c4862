"""fast-downward's PDDL translation runs once per (game, optimise flag) in a process, not four
times per reset (workers/envs/alfworld/translations.py); the game plays exactly as before."""

from __future__ import annotations

import threading

from tests.workers.envs.alfworld.helpers import DATA, HEAT_ID, HEAT_START
from workers.envs.alfworld import AlfworldBenchmark
from workers.envs.alfworld.translations import TRANSLATIONS, TranslationCache


def test_a_game_is_translated_twice_however_often_it_is_reset():
    bench = AlfworldBenchmark(DATA)
    env = bench.make(HEAT_ID)
    try:
        before = TRANSLATIONS.translations
        first = env.reset()
        moved = env.step("go to garbagecan 1")
        again = env.reset()
        third = env.reset()
        # the first reset of this game in the process: its domain+problem as is and optimised
        assert TRANSLATIONS.translations - before in (0, 2)  # 0: an earlier test of this process had it
        after_first = TRANSLATIONS.translations
        env.reset()
        assert TRANSLATIONS.translations == after_first
        assert first.observation == again.observation == third.observation == HEAT_START
        assert moved.observation.startswith("You arrive at loc 31. On the garbagecan 1, you see")
    finally:
        env.close()


def test_each_caller_gets_its_own_copy_of_the_task_and_misses_run_one_at_a_time():
    calls: list[tuple[str, str, bool]] = []
    inside = threading.Semaphore(1)
    overlapped: list[bool] = []

    def translate(domain: str, problem: str, verbose: bool = False, optimize: bool = False):
        overlapped.append(not inside.acquire(blocking=False))
        try:
            calls.append((domain, problem, optimize))
            return {"actions": [domain, problem]}, f"sas:{problem}:{optimize}"
        finally:
            inside.release()

    cache = TranslationCache(size=2)
    a1, sas1 = cache.translate(translate, "d", "p1")
    a2, sas2 = cache.translate(translate, "d", "p1")
    assert (sas1, sas2) == ("sas:p1:False", "sas:p1:False")
    assert a1 == a2 and a1 is not a2  # a deep copy per caller
    a1["actions"].append("changed")
    assert cache.translate(translate, "d", "p1")[0] == {"actions": ["d", "p1"]}
    cache.translate(translate, "d", "p1", optimize=True)
    cache.translate(translate, "d", "p2")  # the cache holds 2: p1/False, the oldest, goes
    cache.translate(translate, "d", "p1")
    assert calls == [("d", "p1", False), ("d", "p1", True), ("d", "p2", False), ("d", "p1", False)]
    assert cache.translations == 4
    threads = [threading.Thread(target=cache.translate, args=(translate, "d", f"q{i}")) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert cache.translations == 12 and not any(overlapped)
