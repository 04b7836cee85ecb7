"""State out to sockets: the stream hub's latest-state fan-out (`hub`), batch frames packed
where the engine is (`frames`), their JSON and binary forms (`wire`), and entity columns in
frames (`entity_frames`).

May import: `sim` and below.
"""
