"""haulprofile: open truck load profiles.

Three parts under one installed name:

* `haulprofile.contract`: the data contract the truck and the workstation share (MCAP topics and
  their record codec, J1939 and OBD-II tables, log file naming);
* `haulprofile.logger`: the in-truck daemon (``haulprofile-logger``);
* `haulprofile.analysis`: the offline suite (``analyze``).
"""
