"""The REST API: the FastAPI app, its routes, request limits and the jobs that run studies."""
