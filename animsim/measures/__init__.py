"""What is measured on a run's state: the watchdog's energy books, linear stability (the
largest stable step of each method), energy drift, the method really run and the energy
parts plotted. The loop and its watchdog use them, and so do the studies above the loop
(:mod:`animsim.analysis`), so they stand below both."""
