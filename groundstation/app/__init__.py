"""The operator's web app: FastAPI + viser in one process (``groundstation serve``)."""
