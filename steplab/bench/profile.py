"""Profile parsing: what XLA runs per iteration of a compiled loop, read from its compiled text."""

from __future__ import annotations

import re


def loop_kernels(compiled_text: str) -> list[dict]:
    """The operations XLA runs per iteration of each while loop in a compiled program.

    From ``jax.jit(f).lower(...).compile().as_text()``: for each while loop, the number of
    fused kernels and of buffer copies in its body, and the loops nested in it. On the CPU
    each costs a roughly fixed few nanoseconds, which for a small system is the step's cost.
    """
    computations, current = {}, None
    for line in compiled_text.splitlines():
        head = re.match(r"^(?:ENTRY )?%(\S+) ", line)
        if head and line.rstrip().endswith("{"):
            current = computations.setdefault(head.group(1), [])
        elif line.startswith("}"):
            current = None
        elif current is not None:
            current.append(line)
    loops = []
    for lines in computations.values():
        for line in lines:
            body = re.search(r" while\(.*body=%([\w.\-]+)", line)
            if body:
                ops = computations.get(body.group(1), [])
                names = [re.match(r"\s*(?:ROOT )?%(\S+) =", op) for op in ops
                         if " fusion(" in op or " copy(" in op]
                loops.append({"kernels": sum(" fusion(" in op for op in ops),
                              "copies": sum(" copy(" in op for op in ops),
                              "nested_loops": sum(" while(" in op for op in ops),
                              "ops": [m.group(1) for m in names if m]})
    return loops


def compiled_text(jitted, *args) -> str:
    return jitted.lower(*args).compile().as_text()
