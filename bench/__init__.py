"""`so101 bench`: the benchmarks (run_bench.py, with cluster_bench.py and real_bench.py) and what they share (common.py).

bench/ sits at the top of the checkout, beside nodes/ and dataflow.yml, which the benchmarks run.
"""
