"""The one admission of every input (``docs/owners.md``, ``docs/security.md``).

Every input — REST, the WebSocket, OSC, the bHaptics stand-in (SDK1 and SDK2), fleet — is
a thin adapter: it translates its protocol, opens one :class:`Handle` per source at the
service's :class:`Admission` (``admission.open(kind, source, principal=...)``) and does
everything through it: ``receive`` (size, rate, renewal), ``down``/``move``/``up``,
``play``/``play_score``, ``close``. The admission holds, from one :class:`InputPolicy`
per input kind (:func:`policy_table`): the owner's deadline (renewed only by a message
of that owner), contacts per owner, message rate and size, the work one message may ask
for, the connection slots and what yields when they are full, the quotas, and stop
voiding (:class:`Arrival`). Shares go first among principals (:func:`principal_for`),
then among a principal's sources.

Modules: :mod:`.policy` (the table), :mod:`.principals` (principals and owner ids),
:mod:`.rate` (a message's verdict), :mod:`.slots` (the connection half: sources in slots,
their size and rate, who yields; usable without an engine, as the fleet's gateway does),
:mod:`.handle` (a source's owner half, over the engine), :mod:`.named` (a handle's plays
by the names its client gives them, a view onto the engine's tables), :mod:`.table` (the
admission).
"""

from phantomtouch.service.admission.handle import Handle
from phantomtouch.service.admission.named import NamedPlay, NamedPlays
from phantomtouch.service.admission.policy import KINDS, InputPolicy, Kind, policy_table
from phantomtouch.service.admission.principals import owner_id, principal_for
from phantomtouch.service.admission.rate import Arrival, Verdict
from phantomtouch.service.admission.slots import Slot, Slots, YieldCallback
from phantomtouch.service.admission.table import Admission

__all__ = [
    "KINDS",
    "Admission",
    "Arrival",
    "Handle",
    "InputPolicy",
    "Kind",
    "NamedPlay",
    "NamedPlays",
    "Slot",
    "Slots",
    "Verdict",
    "YieldCallback",
    "owner_id",
    "policy_table",
    "principal_for",
]
