"""What a user asks graphtwin to do — assemble, calibrate, diagnose, add an effect — each written once
and called by both the CLI and the HTTP service's jobs, with one typed request per kind."""
