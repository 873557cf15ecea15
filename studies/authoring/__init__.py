"""Writing studies as text: the examples, checks of a draft as it is typed, and the study-file
reference (JSON Schema and Markdown).
"""
