"""The papers' tables and claims, measured with this package (importable; the benchmarks call them).

``chaudhari``  Chaudhari (2008) ch. 4: Table 4.1 (frames per second in each model's view of
               highest depth complexity), Table 4.2 (time per stage, with photon generation),
               and the exit-direction error against the exact reference over a ring of views.
"""
