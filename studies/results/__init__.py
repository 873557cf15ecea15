"""What a study leaves behind: the labelled dataset, the store and its catalog, the case table and the
chunk timings.
"""
