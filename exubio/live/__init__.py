"""Live reconstruction from a marker stream (issue 22): causal preprocessing (causal), the live
loop shared with the offline causal run (loop), marker sources (sources: the interface and an
in-process replay; transport: Lab Streaming Layer, the only pylsl user), the recording written as
``exubio reconstruct`` writes a trial (record), and the terminal display (display)."""
