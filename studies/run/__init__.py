"""How a study is answered: cost estimates, the accuracy choice, fan-out over Dask, the runner and the
optimisation loop.
"""
