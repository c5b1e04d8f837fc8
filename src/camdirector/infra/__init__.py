"""Low-level pieces every process shares and none owns: the stage clock, the framing of the
sockets between processes, child-process lifetime, the PostgreSQL connection, the job error."""
