"""The SCSI command handlers of the simulated analyser (INQUIRY, TEST UNIT READY, REQUEST SENSE,
GET CAPABILITIES and the vendor opcodes SET UP, GET SET-UP, ARM, GET STATUS, READ BLOCK, ABORT).

:class:`ScsiCommands` turns a decoded CBW into a :class:`simulator.link.Reply`; it does not see the
link (framing, phases, stalls) and leaves the capture physics (the strike, the ADC, the block) to
:class:`simulator.capture.CaptureEngine`. Sense codes are listed in :mod:`simulator.firmware`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping

import numpy as np

from acquisition import protocol as P
from simulator.capture import CaptureEngine
from simulator.link import GOOD_SENSE, UA_RESET_SENSE, Reply, fail

__all__ = ["ScsiCommands", "IDENTITY", "DEFAULT_SERIAL"]

_log = logging.getLogger("simulator.firmware")

#: vendor, product, revision reported by INQUIRY (and the default serial number, VPD page 0x80)
IDENTITY = P.Inquiry(P.DEVICE_TYPE_PROCESSOR, "IMPACTLB", "SIGLAB-SIM 2042", "0100")
DEFAULT_SERIAL = "SL2042-0000001"


class ScsiCommands(CaptureEngine):
    """Command handlers over the device state that :class:`simulator.firmware.Firmware` holds.

    Needs the attributes ``capabilities``, ``serial``, ``stand``, the acquisition state
    (``_state``, ``_setup`` ...) and the capture methods ``_strike``, ``_give_stand``,
    ``_frontend_config`` (from :class:`simulator.capture.CaptureEngine`).
    """

    capabilities: P.CapabilitiesData
    serial: str
    strike_after_polls: int
    max_strikes: int
    _sense: P.Sense
    _unit_attention: bool
    _handlers: dict[int, Callable[[Mapping[str, int], bytes], Reply]]
    _inquiry_bytes: bytes
    _caps_bytes: bytes

    def _command_table(self) -> dict[int, Callable[[Mapping[str, int], bytes], Reply]]:
        return {
            P.Op.TEST_UNIT_READY: self._test_unit_ready, P.Op.REQUEST_SENSE: self._request_sense,
            P.Op.INQUIRY: self._inquiry, P.Op.GET_CAPABILITIES: self._get_capabilities,
            P.Op.SET_UP: self._set_up, P.Op.GET_SET_UP: self._get_set_up, P.Op.ARM: self._arm,
            P.Op.GET_STATUS: self._get_status, P.Op.READ_BLOCK: self._read_block, P.Op.ABORT: self._abort,
        }

    def _run(self, spec: P.CommandSpec, fields: dict[str, int], data: bytes) -> Reply:
        """Execute one decoded, admitted command with its data-out bytes."""
        return self._handlers[spec.opcode](fields, data)

    def _decode(self, cbw: P.Cbw) -> tuple[P.CommandSpec | None, dict[str, int], Reply | None]:
        """(table row or None, CDB fields, a failure Reply or None when the command may run).

        Order of checks: unsupported opcode (0x20), CDB too short (0x24), LUN other than 0 (0x25),
        pending UNIT ATTENTION (except INQUIRY and REQUEST SENSE), CDB field validation (0x24)."""
        spec = P.COMMANDS.get(cbw.opcode)
        if spec is None:
            return None, {}, fail(P.SenseKey.ILLEGAL_REQUEST, P.ASC_INVALID_OPCODE)
        try:
            spec, fields = P.parse_cdb(cbw.cdb)
        except ValueError:
            return None, {}, fail(P.SenseKey.ILLEGAL_REQUEST, P.ASC_INVALID_FIELD_CDB)
        if cbw.lun != 0:
            return spec, fields, fail(P.SenseKey.ILLEGAL_REQUEST, P.ASC_LUN_NOT_SUPPORTED)
        if self._unit_attention and spec.opcode not in (P.Op.INQUIRY, P.Op.REQUEST_SENSE):
            self._unit_attention = False
            return spec, fields, Reply(P.CswStatus.FAILED, b"", UA_RESET_SENSE)
        err = spec.validate(fields)
        if err:
            _log.debug("%s: %s", spec.name, err)
            return spec, fields, fail(P.SenseKey.ILLEGAL_REQUEST, P.ASC_INVALID_FIELD_CDB)
        return spec, fields, None

    # ------------------------------------------------------------------ commands
    def _test_unit_ready(self, f: Mapping[str, int], data: bytes) -> Reply:
        return Reply()

    def _request_sense(self, f: Mapping[str, int], data: bytes) -> Reply:
        sense = self._sense
        if self._unit_attention:
            sense = UA_RESET_SENSE
            self._unit_attention = False
        self._sense = GOOD_SENSE
        return Reply(data=P.encode_sense(sense)[:f["length"]])

    def _inquiry(self, f: Mapping[str, int], data: bytes) -> Reply:
        if not f["evpd"]:
            payload = self._inquiry_bytes
        elif f["page"] == P.VPD_SERIAL_NUMBER:
            payload = P.encode_serial_vpd(self.serial)
        else:
            payload = P.VPD_HEADER.pack(P.DEVICE_TYPE_PROCESSOR, P.VPD_SUPPORTED_PAGES, 0, 2) + bytes(
                [P.VPD_SUPPORTED_PAGES, P.VPD_SERIAL_NUMBER])
        return Reply(data=payload[:f["length"]])

    def _get_capabilities(self, f: Mapping[str, int], data: bytes) -> Reply:
        return Reply(data=self._caps_bytes[:f["length"]])

    def _set_up(self, f: Mapping[str, int], data: bytes) -> Reply:
        if self._state == P.State.ARMED:
            return fail(P.SenseKey.NOT_READY, P.ASC_NOT_READY_ARMED)
        try:
            setup = P.decode_setup(data)
        except P.ProtocolError as exc:
            _log.debug("SET UP rejected: %s", exc)
            n_declared = data[1] if len(data) >= 2 else -1
            bad_len = len(data) < P.SETUP_HEADER.size or len(data) != P.setup_size(n_declared)
            return fail(P.SenseKey.ILLEGAL_REQUEST,
                         P.ASC_PARAMETER_LENGTH if bad_len else P.ASC_INVALID_FIELD_PARAM)
        problem = self._check_setup(setup)
        if problem:
            _log.debug("SET UP rejected: %s", problem)
            return fail(P.SenseKey.ILLEGAL_REQUEST, P.ASC_INVALID_FIELD_PARAM)
        if self.stand is not None:
            try:
                self._give_stand(setup)
            except ValueError as exc:  # e.g. a point that is not on the simulated frame
                _log.info("SET UP rejected by the test stand: %s", exc)
                return fail(P.SenseKey.ILLEGAL_REQUEST, P.ASC_INVALID_FIELD_PARAM)
        if self.stand is not None:
            from simulator import frontend

            frontend.anti_alias_sos(float(setup.sample_rate_hz), self._frontend_config())  # design once, cached
        self._setup = setup
        self._setup_bytes = P.encode_setup(setup)
        self._state = P.State.IDLE
        self._block = None
        self._cache = None
        return Reply()

    def _check_setup(self, s: P.SetupData) -> str | None:
        caps = self.capabilities
        n = len(s.channels)
        if s.sample_rate_hz not in caps.sample_rates_hz:
            return f"sample rate {s.sample_rate_hz}"
        if s.block_size not in caps.block_sizes:
            return f"block size {s.block_size}"
        if not 1 <= n <= caps.n_inputs:
            return f"{n} channels"
        if not 0 <= s.trigger_channel < n:
            return f"trigger channel {s.trigger_channel}"
        if not 0 <= s.pretrigger < min(s.block_size, caps.max_pretrigger + 1):
            return f"pre-trigger {s.pretrigger}"
        if not np.isfinite(s.trigger_level_v):
            return "trigger level"
        inputs = [c.input for c in s.channels]
        if len(set(inputs)) != n or not all(0 <= i < caps.n_inputs for i in inputs):
            return f"inputs {inputs}"
        for c in s.channels:
            if c.range_mv not in caps.ranges_mv:
                return f"range {c.range_mv} mV"
            if (c.coupling == "AC" and not caps.ac) or (c.coupling == "DC" and not caps.dc):
                return f"coupling {c.coupling}"
            if c.iepe and (not caps.iepe or c.coupling != "AC"):
                return "IEPE needs AC coupling"
            if not (np.isfinite(c.sensitivity) and c.sensitivity > 0):
                return f"sensitivity {c.sensitivity}"
        return None

    def _get_set_up(self, f: Mapping[str, int], data: bytes) -> Reply:
        if self._setup is None:
            return fail(P.SenseKey.NOT_READY, P.ASC_NOT_READY_SETUP_REQUIRED)
        return Reply(data=self._setup_bytes[:f["length"]])

    def _arm(self, f: Mapping[str, int], data: bytes) -> Reply:
        if self._setup is None:
            return fail(P.SenseKey.NOT_READY, P.ASC_NOT_READY_SETUP_REQUIRED)
        if self.stand is None:
            return fail(P.SenseKey.HARDWARE_ERROR, P.ASC_INTERNAL_FAILURE)
        self._start_arm()
        if self.strike_after_polls == 0:
            return self._strike_safely() or Reply()
        return Reply()

    def _strike_safely(self) -> Reply | None:
        """Strike; a stand that cannot (bad request, broken chain) ends the capture with HARDWARE ERROR."""
        try:
            self._strike()
        except (ValueError, RuntimeError) as exc:
            _log.error("the test stand failed to strike: %s", exc)
            self._state = P.State.IDLE
            return fail(P.SenseKey.HARDWARE_ERROR, P.ASC_INTERNAL_FAILURE)
        return None

    def _get_status(self, f: Mapping[str, int], data: bytes) -> Reply:
        if self._state == P.State.ARMED:
            self._polls += 1
            if self._polls > self.strike_after_polls and self._strikes < self.max_strikes:
                failed = self._strike_safely()
                if failed is not None:
                    return failed
        n = self.block_samples
        st = P.StatusData(self._state, self._overload_mask, self._setup is not None, self._no_trigger,
                          self._sequence, n if self._state == P.State.BLOCK_READY else 0, self._strikes)
        return Reply(data=P.encode_status(st)[:f["length"]])

    def _read_block(self, f: Mapping[str, int], data: bytes) -> Reply:
        if self._state != P.State.BLOCK_READY or self._block is None:
            return fail(P.SenseKey.NOT_READY, P.ASC_NOT_READY_NO_BLOCK)
        if f["sequence"] != self._sequence or f["offset"] >= len(self._block):
            return fail(P.SenseKey.ILLEGAL_REQUEST, P.ASC_INVALID_FIELD_CDB)
        start = f["offset"]
        return Reply(data=memoryview(self._block)[start:start + f["count"]])

    def _abort(self, f: Mapping[str, int], data: bytes) -> Reply:
        if self._state in (P.State.ARMED, P.State.TRIGGERED):
            self._state = P.State.IDLE
        return Reply()
