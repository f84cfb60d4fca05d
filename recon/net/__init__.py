"""The paper's reconstruction network (section 5, Fig. 3): MSFEG, SPA, LIR, and its training and use."""
