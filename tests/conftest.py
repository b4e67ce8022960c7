import torch as th

# Tiny networks on a small shared CI machine: one intra-op thread is several times faster than contended threads
th.set_num_threads(1)
