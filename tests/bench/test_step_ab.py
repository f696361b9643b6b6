from nerf2gs_bench.step_ab import interleaved_step_cpu


def test_blocks_alternate_after_before_before_after_and_every_step_runs_once():
    state, seen = {"after": None}, []

    class Trainer:
        def train_step(self, step: int) -> None:
            seen.append((step, state["after"]))
            sum(i * i for i in range(2000))  # some CPU time for each side

    per = interleaved_step_cpu(Trainer(), lambda after: state.update(after=after), start=10, steps=80, block=10)
    assert [s for s, _ in seen] == list(range(10, 90))
    assert [a for s, a in seen if s % 10 == 0] == [True, False, False, True] * 2
    assert set(per) == {"after", "before"} and per["after"] > 0 and per["before"] > 0
