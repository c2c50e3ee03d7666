"""``python -m acquisition identify --device URL``: print the analyser's identity and capabilities."""
from __future__ import annotations

import argparse
import json
from collections.abc import Sequence

from acquisition.errors import ImpactlabError, InvalidDeviceURL, UsageError
from analysis.command_line import add_json_flag, add_verbose, cli_entry, exit_on, set_verbosity, with_examples

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m acquisition identify",
                                description="Open a device URL and print the analyser's identity and capabilities.")
    with_examples(p)
    p.add_argument("--device", required=True, help="device URL, e.g. sim://?seed=1, socket://127.0.0.1:5025, "
                                                   "/dev/ttyUSB0, usb://1209:4c41, usbsim://")
    p.add_argument("--timeout", type=float, default=2.0, help="seconds allowed per command (default 2)")
    add_json_flag(p)
    add_verbose(p)
    return p


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    set_verbosity(args.verbose)
    from acquisition.driver import Analyser

    # the same code as every command for the same problem: a bad URL is a usage error (2), a device
    # that does not answer is a device failure (1)
    with exit_on("identify", ((InvalidDeviceURL, UsageError), 2), ((ImpactlabError, OSError), 1)):
        with Analyser(args.device, timeout_s=args.timeout) as an:
            ident = an.identify()
            caps = an.capabilities()
    if args.json:
        out = {"identity": ident.as_dict(), "capabilities": {
            "inputs": caps.n_inputs, "sample_rates_hz": list(caps.sample_rates_hz),
            "bandwidths_hz": [round(b, 3) for b in caps.bandwidths_hz()], "ranges_v": list(caps.ranges_v),
            "block_sizes": list(caps.block_sizes), "couplings": list(caps.couplings), "iepe": caps.iepe,
            "trigger_any_channel": caps.trigger_any_channel, "adc_bits": caps.adc_bits,
            "max_pretrigger": caps.max_pretrigger, "max_transfer_bytes": caps.max_transfer}}
        print(json.dumps(out, indent=2))
        return 0
    print(f"device       {ident.url or args.device}")
    print(f"vendor       {ident.vendor}")
    print(f"product      {ident.product}")
    print(f"revision     {ident.revision}")
    print(f"serial       {ident.serial}")
    print(f"protocol     v{ident.protocol_version}")
    print(f"inputs       {caps.n_inputs} ({', '.join(caps.couplings)} coupling{', IEPE' if caps.iepe else ''}, "
          f"{caps.adc_bits}-bit)")
    print("sample rates " + ", ".join(f"{r:g}" for r in caps.sample_rates_hz) + " Hz (bandwidth fs/2.56)")
    print("ranges       " + ", ".join(f"{r:g}" for r in caps.ranges_v) + " V")
    print("block sizes  " + ", ".join(str(b) for b in caps.block_sizes) + " samples")
    print(f"trigger      any channel, level, slope, up to {caps.max_pretrigger} pre-trigger samples")
    return 0
