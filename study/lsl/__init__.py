"""The lab's other instruments, through the Lab Streaming Layer (LSL).

A session publishes its markers and its samples as LSL streams (`publish`), records
the streams the design names during its trials (`record`), and LabRecorder's XDF files
are imported by the project's markers (`xdf`). Recorded streams are stored in their
own tables (`store`, `db.models.lsl`), each sample on the trial's clock.

pylsl is imported only through `study.lsl.config.load_pylsl`, which refuses to load it
unless `LSLAPICFG` names a liblsl configuration file: liblsl's defaults send discovery
packets to multicast and broadcast addresses, which a lab decides on, not this tool.
The session runner knows this package only through the observer it is handed
(`study.protocol.observer.SessionObserver`).
"""
