"""The CiA 402 states of a simulated drive: what its statusword shows in each, and where a
controlword takes it."""

from __future__ import annotations

from foosball_gym.real_table.hardware.cia402.protocol import OPERATION_ENABLED

SOD = "SWITCH ON DISABLED"
READY = "READY TO SWITCH ON"
SWITCHED_ON = "SWITCHED ON"
QUICK_STOP = "QUICK STOP ACTIVE"
FAULT = "FAULT"
# Statusword bits 0-6 of each state (voltage enabled included), as a C5-E shows them.
STATE_BITS = {
    SOD: 0x40,
    READY: 0x31,
    SWITCHED_ON: 0x33,
    OPERATION_ENABLED: 0x37,
    QUICK_STOP: 0x17,
    FAULT: 0x08,
}
SW_REMOTE = 0x0200
# The drive function (power stage driving the motor) is on in these states.
POWERED = (OPERATION_ENABLED, QUICK_STOP)
SW_BIT12 = 0x1000  # pp: set-point acknowledge; csp: the drive follows the command value


def next_state(state: str, cw: int, quick_stop_option: int) -> str:
    """The state controlword ``cw`` takes a drive in ``state`` to (FAULT is left by a fault
    reset only, which the caller handles).

    ``quick_stop_option`` is the drive's quick stop option code (0x605A): only codes 5-8 stay
    in QUICK STOP ACTIVE, and only from there does enable operation lead back.
    """
    if not cw & 0x02:  # disable voltage
        return SOD if state in (READY, SWITCHED_ON, OPERATION_ENABLED, QUICK_STOP) else state
    if not cw & 0x04:  # quick stop
        return {OPERATION_ENABLED: QUICK_STOP, READY: SOD, SWITCHED_ON: SOD}.get(state, state)
    if not cw & 0x01:  # shutdown
        return READY if state in (SOD, SWITCHED_ON, OPERATION_ENABLED) else state
    if not cw & 0x08:  # switch on, disable operation
        return SWITCHED_ON if state in (READY, OPERATION_ENABLED) else state
    # Enable operation; out of QUICK STOP ACTIVE only with the option codes that stay there.
    if state == QUICK_STOP and not 5 <= quick_stop_option <= 8:
        return state
    return OPERATION_ENABLED if state in (READY, SWITCHED_ON, QUICK_STOP) else state
