# The TableTeach study server. Built by docker-compose.yml (PostgreSQL + migrations + app processes + nginx).
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PIP_NO_CACHE_DIR=1
WORKDIR /app

# Editable install: the migrations (alembic.ini, alembic/) are read from the source tree in /app.
COPY pyproject.toml README.md ./
COPY backend ./backend
COPY alembic ./alembic
COPY alembic.ini ./
COPY frontend ./frontend
COPY sim_assets ./sim_assets
RUN pip install -e . "psycopg[binary]>=3.1,<4"

# var/data exists and belongs to the app user, so a named volume mounted there (recordings) does too.
RUN useradd --create-home --uid 10001 tableteach && mkdir -p /app/var/data && chown -R tableteach /app/var
USER tableteach

ENV TABLETEACH_HOST=0.0.0.0 TABLETEACH_PORT=8000
EXPOSE 8000
HEALTHCHECK --interval=10s --timeout=3s --retries=5 \
  CMD python -c "import urllib.request; urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=2)"
CMD ["tableteach", "serve"]
