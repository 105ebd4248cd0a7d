"""`python -m rssp1 inspect FILE.pcapng --device ADDR:SID1,SID2`."""

from rssp1.cli import app

app(prog_name="python -m rssp1")
