"""The barrier at which the DEM threads meet at the end of a step (`threads.run_share`), and the
flags by which a thread tells the others that its part of the step's contacts between two
threads' bodies is worked out: a thread that arrives early spins, and sleeps only if the others
are long in coming.

A step of 10 000 spheres takes about a fifth of a millisecond on each of two threads. At a
barrier that puts the first thread to arrive to sleep at once (as the C library's pthread
barrier does), nearly every meeting costs two system calls and a wake-up (6 300 sleeps in 3 083
steps, measured), and two threads took 1.39 times one thread's CPU for 1.14 times its speed on
a quiet machine. Spinning, a meeting costs the time by which the threads' shares differ. The spin is
bounded (SPIN_CYCLES, about 40 microseconds): a thread whose partner has lost its core to other
work sleeps on a futex rather than hold a core that the partner may need.

The barrier is a counter and a generation in a shared block, updated with atomic operations
(numba intrinsics); each thread holds a row of its own (`barrier_wait`'s argument): the block's
address, then its counts (meetings, sleeps, cycles spent waiting), in cache lines of its own.
A flag is a count in its thread's row (`raise_flag`: how many steps' parts it has done), which
another thread waits to reach its own count (`wait_flag`): a one-way meeting, the raiser never
waits. Interpreted, the same protocol runs on a condition variable.
"""

from __future__ import annotations

import ctypes
import platform
import sys
import threading

import numpy as np

from collide.engine import tier
from collide.engine.jit import jit, jit_inline

# A thread's row (int64): the shared block's address, meetings, sleeps, cycles waited (at the
# barrier and at flags), flags waited for (not raised when first looked at), flags raised, the
# thread's number; then, in the next cache line (read by the
# other threads), its flag and the threads asleep on it. Padded to 128 bytes so that no two
# threads' rows share a cache line.
W_BLOCK, W_MEETS, W_SLEEPS, W_CYCLES, W_FLAGWAITS, W_RAISED, W_INDEX = 0, 1, 2, 3, 4, 5, 6
W_FLAG, W_FLAGSLEEPERS = 8, 9
ROW = 16
# The shared block: threads arrived, generation (the futex word: its low 32 bits), sleepers,
# threads, cycles to spin before sleeping.
B_COUNT, B_GEN, B_SLEEPERS, B_THREADS, B_SPIN = 0, 1, 2, 3, 4
# About 40 microseconds at 2.5 GHz: longer than the threads' shares of a step differ by, shorter
# than a scheduler's time slice.
SPIN_CYCLES = 100_000

_FUTEX_CALL = {"x86_64": 202, "aarch64": 98}.get(platform.machine())  # (the futex system call's number)
_FUTEX_WAIT_PRIVATE, _FUTEX_WAKE_PRIVATE = 128, 129
# The processor's spin-wait hint (LLVM's intrinsic and its argument, if it takes one).
_PAUSE = {"x86_64": ("llvm.x86.sse2.pause", None), "aarch64": ("llvm.aarch64.hint", 1)}.get(platform.machine())
# Where the threads run together: Linux (futexes). Elsewhere a run takes one thread.
HAVE_BARRIER = sys.platform == "linux" and _FUTEX_CALL is not None


def rows(threads: int) -> np.ndarray:
    """The barrier for `threads` threads: (threads + 1, ROW) int64, thread r's row r (each with
    the block's address), the shared block last. The caller keeps the array alive while any
    thread may wait."""
    table = np.zeros((threads + 1, ROW), np.int64)
    block = table[threads]
    block[B_THREADS], block[B_SPIN] = threads, SPIN_CYCLES
    table[:threads, W_BLOCK] = block.ctypes.data
    table[:threads, W_INDEX] = np.arange(threads)
    return table


def _row_address(block: int, threads: int, r: int) -> int:
    """Thread r's row's address, from the shared block's (the table's last row)."""
    return block - (threads - r) * ROW * 8


if tier.COMPILED and HAVE_BARRIER:
    import llvmlite.binding as llvm
    from llvmlite import ir
    from numba.core import cgutils, types
    from numba.extending import intrinsic

    _libc = ctypes.CDLL(None)
    llvm.add_symbol("syscall", ctypes.cast(_libc.syscall, ctypes.c_void_p).value)
    _syscall = types.ExternalFunction("syscall", types.int64(types.int64, types.int64, types.int64, types.int64,
                                                             types.int64))
    _I64 = ir.IntType(64)

    def _slot(builder, address, slot):
        return builder.inttoptr(builder.add(address, builder.mul(slot, ir.Constant(_I64, 8))), _I64.as_pointer())

    @intrinsic
    def _load(typingctx, address, slot):
        """block[slot], read atomically (sequentially consistent)."""
        def codegen(context, builder, signature, args):
            return builder.load_atomic(_slot(builder, *args), "seq_cst", 8)
        return types.int64(types.int64, types.int64), codegen

    @intrinsic
    def _store(typingctx, address, slot, value):
        """block[slot] = value, atomically (sequentially consistent)."""
        def codegen(context, builder, signature, args):
            builder.store_atomic(args[2], _slot(builder, args[0], args[1]), "seq_cst", 8)
            return context.get_dummy_value()
        return types.none(types.int64, types.int64, types.int64), codegen

    @intrinsic
    def _add(typingctx, address, slot, value):
        """block[slot] += value atomically; returns the value before."""
        def codegen(context, builder, signature, args):
            return builder.atomic_rmw("add", _slot(builder, args[0], args[1]), args[2], "seq_cst")
        return types.int64(types.int64, types.int64, types.int64), codegen

    @intrinsic
    def _pause(typingctx):
        """The processor's spin-wait hint."""
        def codegen(context, builder, signature, args):
            if _PAUSE is not None:
                name, operand = _PAUSE
                kind = ir.FunctionType(ir.VoidType(), [] if operand is None else [ir.IntType(32)])
                hint = cgutils.get_or_insert_function(builder.module, kind, name)
                builder.call(hint, [] if operand is None else [ir.Constant(ir.IntType(32), operand)])
            return context.get_dummy_value()
        return types.none(), codegen

    @intrinsic
    def _cycles(typingctx):
        """The processor's cycle counter (the time-stamp counter on x86-64)."""
        def codegen(context, builder, signature, args):
            read = cgutils.get_or_insert_function(builder.module, ir.FunctionType(_I64, []), "llvm.readcyclecounter")
            return builder.call(read, [])
        return types.int64(), codegen

    @jit_inline
    def barrier_wait(own):
        """Wait until every thread has called this as often (own: the thread's row of `rows`).
        The last to arrive starts the next generation and wakes any sleeper."""
        block = own[W_BLOCK]
        start = _cycles()
        gen = _load(block, B_GEN)
        if _add(block, B_COUNT, 1) == _load(block, B_THREADS) - 1:
            _store(block, B_COUNT, 0)
            _store(block, B_GEN, gen + 1)
            if _load(block, B_SLEEPERS) > 0:
                _syscall(_FUTEX_CALL, block + 8 * B_GEN, _FUTEX_WAKE_PRIVATE, 2147483647, 0)
        else:
            _wait_while(block + 8 * B_GEN, block + 8 * B_SLEEPERS, gen, start, _load(block, B_SPIN), own)
        own[W_MEETS] += 1
        own[W_CYCLES] += _cycles() - start
        return 0

    @jit_inline
    def _wait_while(word, sleepers, value, start, spin, own):
        """Wait while the int64 at address `word` holds `value`: spinning until `spin` cycles
        from `start`, then asleep on it (a futex on its low 32 bits), counted in the int64 at
        `sleepers` so that whoever changes it wakes the sleepers."""
        while _load(word, 0) == value:
            if _cycles() - start < spin:
                _pause()
                continue
            # Counted as a sleeper before the last look: the thread that changes the word either
            # sees the count and wakes us, or has changed it, which the futex sees.
            _add(sleepers, 0, 1)
            if _load(word, 0) == value:
                _syscall(_FUTEX_CALL, word, _FUTEX_WAIT_PRIVATE, value & 0xFFFFFFFF, 0)
                own[W_SLEEPS] += 1
            _add(sleepers, 0, -1)

    @jit_inline
    def raise_flag(own):
        """This thread's part of a step done: its flag raised to the count of its steps' parts,
        any thread asleep on it woken."""
        own[W_RAISED] += 1
        row = _row(own[W_BLOCK], _load(own[W_BLOCK], B_THREADS), own[W_INDEX])
        _store(row, W_FLAG, own[W_RAISED])
        if _load(row, W_FLAGSLEEPERS) > 0:
            _syscall(_FUTEX_CALL, row + 8 * W_FLAG, _FUTEX_WAKE_PRIVATE, 2147483647, 0)
        return 0

    @jit_inline
    def wait_flag(own, other):
        """Wait until thread `other` has raised its flag as often as this thread has its own
        (spinning, then asleep, as `barrier_wait`); counted if it was not raised already."""
        block = own[W_BLOCK]
        row = _row(block, _load(block, B_THREADS), other)
        seen = _load(row, W_FLAG)
        if seen >= own[W_RAISED]:
            return 0
        start = _cycles()
        while seen < own[W_RAISED]:
            _wait_while(row + 8 * W_FLAG, row + 8 * W_FLAGSLEEPERS, seen, start, _load(block, B_SPIN), own)
            seen = _load(row, W_FLAG)
        own[W_FLAGWAITS] += 1
        own[W_CYCLES] += _cycles() - start
        return 0

    @jit_inline
    def _row(block, threads, r):
        """Thread r's row's address (`_row_address`)."""
        return block - (threads - r) * ROW * 8

    @jit
    def cycles():
        """The cycle counter."""
        return _cycles()
else:
    import time

    _CONDITION = threading.Condition()

    def barrier_wait(own: np.ndarray) -> int:
        """Interpreted: the same barrier on a condition variable (cycles counted in nanoseconds)."""
        block = (ctypes.c_int64 * ROW).from_address(int(own[W_BLOCK]))
        start = time.perf_counter_ns()
        with _CONDITION:
            gen = block[B_GEN]
            block[B_COUNT] += 1
            if block[B_COUNT] == block[B_THREADS]:
                block[B_COUNT] = 0
                block[B_GEN] = gen + 1
                _CONDITION.notify_all()
            while block[B_GEN] == gen:
                _CONDITION.wait()
        own[W_MEETS] += 1
        own[W_CYCLES] += time.perf_counter_ns() - start
        return 0

    def _flag_row(own: np.ndarray, r: int):
        block = int(own[W_BLOCK])
        threads = (ctypes.c_int64 * ROW).from_address(block)[B_THREADS]
        return (ctypes.c_int64 * ROW).from_address(_row_address(block, threads, r))

    def raise_flag(own: np.ndarray) -> int:
        """Interpreted: `raise_flag` on the condition variable."""
        with _CONDITION:
            own[W_RAISED] += 1
            own[W_FLAG] = own[W_RAISED]
            _CONDITION.notify_all()
        return 0

    def wait_flag(own: np.ndarray, other: int) -> int:
        """Interpreted: `wait_flag` on the condition variable."""
        row = _flag_row(own, other)
        start = time.perf_counter_ns()
        with _CONDITION:
            if row[W_FLAG] >= own[W_RAISED]:
                return 0
            while row[W_FLAG] < own[W_RAISED]:
                _CONDITION.wait()
        own[W_FLAGWAITS] += 1
        own[W_CYCLES] += time.perf_counter_ns() - start
        return 0

    def cycles() -> int:
        """Interpreted: nanoseconds."""
        return time.perf_counter_ns()
