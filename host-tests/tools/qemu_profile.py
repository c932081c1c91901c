#!/usr/bin/env python3
"""Where a firmware example's instructions go, under QEMU, by function or
by source line: a developer's profiler for the cost rounds (docs/cost.md,
"Profiling on the target"). Not part of CI.

It starts the example in QEMU as .ci/run does (-icount shift=7), switches
QEMU's executed-block log on through the monitor for a window of wall
seconds, and charges each executed block its instructions (the block's
length read from the disassembly: to its first branch, within QEMU's
1 KiB page). Compiler routines (soft-float, 64-bit shifts, memcpy) are
charged to the code that called them. Source lines come from the ELF's
debug info (the `firmware` profile keeps it), the innermost frame in this
crate's `src/`.

Needs qemu-system-arm, llvm-objdump and llvm-symbolizer (Debian's `llvm`).

    cargo build -p coil-thermal --profile firmware --features firmware,integer-step \\
        --example motor_qemu --target thumbv6m-none-eabi
    host-tests/tools/qemu_profile.py target/thumbv6m-none-eabi/firmware/examples/motor_qemu \\
        --cpu m0 --by line --tick-entry 'NetworkObserver<_,_,_,_,_>::tick' --ticks-calling fuse_readings
"""
import argparse
import bisect
import collections
import os
import re
import socket
import subprocess
import tempfile
import time



def ends_block(op, operands):
    """An instruction after which QEMU starts a new block: a branch, a call,
    a return, a trap."""
    if op.startswith("b") and not op.startswith(("bic", "bfi", "bfc")):
        return True
    if op.startswith(("cbz", "cbnz", "svc", "udf")):
        return True
    return op.startswith(("pop", "ldm")) and "pc" in operands or op.startswith("mov") and operands.startswith("pc")


def run_qemu(elf, cpu, start_s, window_s, log):
    """Runs the example and logs the executed blocks over the window."""
    machine = (["-cpu", "cortex-m0", "-machine", "microbit", "-global", "nrf51-soc.sram-size=65536"]
               if cpu == "m0" else ["-cpu", "cortex-m4", "-machine", "mps2-an386"])
    sock = os.path.join(os.path.dirname(log), "monitor.sock")
    qemu = subprocess.Popen(
        ["qemu-system-arm", *machine, "-nographic", "-icount", "shift=7",
         "-semihosting-config", "enable=on,target=native", "-kernel", elf,
         "-monitor", f"unix:{sock},server=on,wait=off", "-D", log],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(start_s)
    monitor = socket.socket(socket.AF_UNIX)
    monitor.connect(sock)
    for command, pause in (("log exec,nochain", window_s), ("log none", 0.2), ("quit", 0.2)):
        monitor.sendall((command + "\n").encode())
        time.sleep(pause)
    qemu.wait()


class Image:
    """The ELF's instructions, symbols and source lines."""

    def __init__(self, elf):
        self.elf = elf
        self.addrs, self.branch, symbols = [], {}, []
        text = subprocess.run(["llvm-objdump", "-d", "-C", "--no-show-raw-insn", elf],
                              capture_output=True, text=True, check=True).stdout
        for line in text.splitlines():
            if m := re.match(r"^([0-9a-f]+) <(.+)>:$", line):
                if not m.group(2).startswith("$"):  # mapping symbols ($t, $d)
                    symbols.append((int(m.group(1), 16), readable(m.group(2))))
            elif m := re.match(r"^\s+([0-9a-f]+):\s+(\S+)\s*(.*)$", line):
                addr, op, rest = int(m.group(1), 16), m.group(2), m.group(3)
                self.addrs.append(addr)
                self.branch[addr] = ends_block(op, rest)
        self.addrs.sort()
        symbols.sort()
        self.sym_addr = [a for a, _ in symbols]
        self.sym_name = [n for _, n in symbols]
        self.blocks = {}

    def block(self, pc):
        """The instructions of the block QEMU starts at `pc`."""
        if pc not in self.blocks:
            i, out, page_end = bisect.bisect_left(self.addrs, pc), [], (pc & ~0x3FF) + 0x400
            while i < len(self.addrs) and self.addrs[i] < page_end and len(out) < 512:
                out.append(self.addrs[i])
                if self.branch[self.addrs[i]]:
                    break
                i += 1
            self.blocks[pc] = out
        return self.blocks[pc]

    def symbol(self, pc):
        i = bisect.bisect_right(self.sym_addr, pc) - 1
        return self.sym_name[i] if i >= 0 else "?"

    def entries(self, suffix):
        """The entries of the functions whose names end in `suffix`."""
        return {a for a, n in zip(self.sym_addr, self.sym_name) if n.endswith(suffix)}

    def lines(self, pcs):
        """Each pc's innermost source frame in this crate (else the innermost)."""
        pcs = sorted(pcs)
        out = subprocess.run(["llvm-symbolizer", f"--obj={self.elf}", "-i", "-C"],
                             input="\n".join(hex(p) for p in pcs), capture_output=True,
                             text=True, check=True).stdout
        where = {}
        for pc, chunk in zip(pcs, out.strip("\n").split("\n\n")):
            rows = chunk.split("\n")
            frames = list(zip(rows[0::2], rows[1::2]))
            ours = [f for f in frames if "/src/" in f[1] and "/rustc/" not in f[1] and "/.cargo/" not in f[1]]
            function, place = (ours or frames or [("?", "?")])[0]
            place = re.sub(r":\d+$", "", re.sub(r"^.*?/(src|examples)/", r"\1/", place))
            where[pc] = f"{place}  {readable(function)[-70:]}"
        return where


def readable(name):
    """A Rust symbol as its path, without the legacy mangling's escapes and
    hash (llvm-objdump 14 leaves them)."""
    for escape, char in (("$LT$", "<"), ("$GT$", ">"), ("$C$", ","), ("$u20$", " "),
                         ("$u7b$", "{"), ("$u7d$", "}"), ("$RF$", "&"), ("..", "::")):
        name = name.replace(escape, char)
    return re.sub(r"::h[0-9a-f]{16}$", "", name)


def is_routine(name):
    """A compiler routine, charged to its caller."""
    return name.startswith("__") or "compiler_builtins" in name or name in ("memcpy", "memmove", "memset")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("elf")
    ap.add_argument("--cpu", choices=("m0", "m4"), default="m0")
    ap.add_argument("--start", type=float, default=5.0, help="wall seconds before the window")
    ap.add_argument("--window", type=float, default=3.0, help="wall seconds logged")
    ap.add_argument("--by", choices=("function", "line"), default="function")
    ap.add_argument("--tick-entry", help="the function whose entry starts a tick (a suffix of its path)")
    ap.add_argument("--ticks-calling", help="only the ticks that enter this function (a suffix of its path)")
    ap.add_argument("--ticks-without", action="append", default=[],
                    help="only the ticks that do not enter this function (repeatable)")
    ap.add_argument("--heaviest", type=int, help="only the N heaviest ticks")
    ap.add_argument("--rows", type=int, default=30)
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        log = os.path.join(tmp, "exec.log")
        run_qemu(args.elf, args.cpu, args.start, args.window, log)
        seq = []
        with open(log, errors="replace") as f:
            for line in f:
                if line.startswith("Trace") and (m := re.search(r"\[[0-9a-f]+/([0-9a-f]+)/", line)):
                    seq.append(int(m.group(1), 16))
    image = Image(args.elf)
    ticks = [seq]
    if args.tick_entry:
        starts, ticks, current = image.entries(args.tick_entry), [], []
        for pc in seq:
            if pc in starts and current:
                ticks.append(current)
                current = []
            current.append(pc)
        ticks.append(current)
        ticks = ticks[1:-1]  # the window cuts the first and the last
    if args.ticks_calling:
        marks = image.entries(args.ticks_calling)
        ticks = [t for t in ticks if any(pc in marks for pc in t)]
    for name in args.ticks_without:
        marks = image.entries(name)
        ticks = [t for t in ticks if not any(pc in marks for pc in t)]
    cost = lambda tick: sum(len(image.block(pc)) for pc in tick)
    if args.heaviest:
        ticks = sorted(ticks, key=cost, reverse=True)[:args.heaviest]
    where = image.lines({a for t in ticks for pc in set(t) for a in image.block(pc)}) if args.by == "line" else {}
    charged, caller = collections.Counter(), "?"
    for tick in ticks:
        for pc in tick:
            block, name = image.block(pc), image.symbol(pc)
            if is_routine(name):
                charged[caller] += len(block)
                continue
            if args.by == "line":
                for addr in block:
                    charged[where[addr]] += 1
                caller = where[block[-1]] if block else caller
            else:
                charged[name] += len(block)
                caller = name
    if not ticks:
        raise SystemExit("no tick in the window: check --tick-entry and --ticks-calling")
    total = sum(charged.values())
    per = f", {total / len(ticks):.0f} a tick over {len(ticks)} ticks" if args.tick_entry else ""
    print(f"{total} instructions in the window{per} (compiler routines charged to their callers)")
    for name, n in charged.most_common(args.rows):
        print(f"{100 * n / max(total, 1):6.2f}% {n:11d}  {name[:150]}")


if __name__ == "__main__":
    main()
