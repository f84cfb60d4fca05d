"""Amaranth HDL of the camera (SPEC sections 1, 3, 4, 6), on golden's configuration.

:mod:`.pixel` (the TE and ML pixels), :mod:`.timing` (the timing one array shares),
:mod:`.array` (the parallel top: every word on one frame bus), :mod:`.stream` (the streaming
top: words leave in beats of N lanes), :mod:`.verilog` and :mod:`.verilog_stream` (the Verilog
text ``tespike verilog`` writes, a module per pixel site in generate loops), :mod:`.names`
(every generated module's name).
"""
