"""Run one fuzz target of tests/_fuzz.py under atheris (libFuzzer), coverage-guided over servobus's
Python code; bench/reliability.py starts one process of this per target and reads its output.

    python bench/_fuzz_one.py TARGET [CORPUS_DIR] [libFuzzer options, e.g. -runs=1000000 -max_len=512]
    python bench/_fuzz_one.py TARGET --mutate CORPUS_DIR -runs=N [-seed=S] [-max_len=L]

The first form is atheris, coverage-guided, growing CORPUS_DIR. The second runs every input of
CORPUS_DIR, then mutates them (bit flips, byte runs inserted, deleted or overwritten, splices of two
inputs, fresh random inputs) for N inputs in all, with no coverage feedback: it is how the target runs
with the C core under ASan + UBSan, where libFuzzer's coverage cannot work (gcc's libasan, preloaded
into an uninstrumented Python, supplies the coverage hooks in libFuzzer's place, and atheris then
sees no coverage at all). Without atheris the first form falls back to the second with no corpus.
The last line says how many inputs ran either way.
"""

from __future__ import annotations

import random
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))


def _mutate(rng: random.Random, data: bytes, corpus: list[bytes], max_len: int) -> bytes:
    out = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        how = rng.randrange(6)
        at = rng.randint(0, len(out))
        if how == 0 and out:  # flip a bit
            i = rng.randrange(len(out))
            out[i] ^= 1 << rng.randrange(8)
        elif how == 1:  # insert a run of random or repeated bytes
            n = rng.randint(1, 16)
            out[at:at] = rng.randbytes(n) if rng.random() < 0.5 else bytes([rng.randrange(256)]) * n
        elif how == 2 and out:  # delete a run
            del out[at : at + rng.randint(1, 16)]
        elif how == 3 and out:  # overwrite a byte with an interesting value
            out[rng.randrange(len(out))] = rng.choice(
                (0, 1, 0x3E, 0x7F, 0x80, 0xFE, 0xFF, rng.randrange(256))
            )
        elif how == 4 and corpus:  # splice with another input
            other = rng.choice(corpus)
            cut = rng.randint(0, len(other))
            out = out[:at] + bytearray(other[cut:])
        else:  # duplicate a piece of itself
            piece = bytes(out[at : at + rng.randint(1, 32)])
            out[rng.randint(0, len(out)) : 0] = piece
    return bytes(out[:max_len])


def _no_coverage(name: str, argv: list[str], corpus_dir: str | None) -> None:
    import _fuzz

    runs = next((int(a.split("=", 1)[1]) for a in argv if a.startswith("-runs=")), 100_000)
    seed = next((int(a.split("=", 1)[1]) for a in argv if a.startswith("-seed=")), 1)
    max_len = next((int(a.split("=", 1)[1]) for a in argv if a.startswith("-max_len=")), 512)
    corpus = sorted(p.read_bytes() for p in Path(corpus_dir).iterdir()) if corpus_dir else []
    rng = random.Random(seed)
    run = _fuzz.TARGETS[name]
    started = time.perf_counter()
    for i in range(runs):
        if i < len(corpus):
            data = corpus[i]
        elif corpus and rng.random() < 0.9:
            data = _mutate(rng, rng.choice(corpus), corpus, max_len)
        else:
            data = rng.randbytes(rng.randint(0, max_len))
        try:
            run(data)
        except BaseException:
            print(f"crash input: {data.hex()}", flush=True)
            raise
        if i and i % 100_000 == 0:
            print(f"#{i} inputs in {time.perf_counter() - started:.0f} s", flush=True)
    _fuzz.close_rigs()
    elapsed = time.perf_counter() - started
    print(f"Done {runs} runs in {round(elapsed)} second(s) ({len(corpus)} from the corpus)", flush=True)


def main() -> None:
    name, argv = sys.argv[1], sys.argv[2:]
    if "--mutate" in argv:
        i = argv.index("--mutate")
        _no_coverage(name, argv[:i] + argv[i + 2 :], argv[i + 1])
        return
    try:
        import atheris
    except ModuleNotFoundError:
        _no_coverage(name, argv, None)
        return
    with atheris.instrument_imports(include=["servobus", "_fuzz"]):
        import _fuzz
    run = _fuzz.TARGETS[name]

    def one(data: bytes) -> None:
        run(data)

    atheris.Setup([sys.argv[0], *argv], one)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
