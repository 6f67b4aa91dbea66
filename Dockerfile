# The TableTeach study server. Built by docker-compose.yml (PostgreSQL + migrations + app processes + nginx + backups).
#
# Two stages: `build` installs the exact versions of constraints.txt into a virtualenv; the runtime stage copies
# that virtualenv and the source, adds PostgreSQL's client programs (pg_dump/pg_restore for `tableteach backup`)
# and runs as an unprivileged user. Debian trixie's postgresql-client (17) can dump the PostgreSQL 16 server.

FROM python:3.11-slim-trixie AS build
ENV PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1
WORKDIR /app
RUN python -m venv /opt/venv
# The pinned versions first, so a source change does not reinstall every dependency.
COPY constraints.txt ./
COPY pyproject.toml README.md LICENSE ./
COPY backend ./backend
# Editable: the server reads frontend/, sim_assets/ and the migrations (alembic.ini, alembic/) next to backend/.
RUN /opt/venv/bin/pip install --constraint constraints.txt -e . "psycopg[binary]"

FROM python:3.11-slim-trixie
ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PATH=/opt/venv/bin:$PATH
RUN apt-get update \
 && apt-get install -y --no-install-recommends postgresql-client \
 && rm -rf /var/lib/apt/lists/*
WORKDIR /app
COPY --from=build /opt/venv /opt/venv
COPY pyproject.toml README.md LICENSE constraints.txt ./
COPY backend ./backend
COPY alembic ./alembic
COPY alembic.ini ./
COPY frontend ./frontend
COPY sim_assets ./sim_assets

# var/data and var/backups exist and belong to the app user, so named volumes mounted there (recordings,
# backups) do too.
RUN useradd --create-home --uid 10001 tableteach \
 && mkdir -p /app/var/data /app/var/backups && chown -R tableteach /app/var
USER tableteach

ENV TABLETEACH_HOST=0.0.0.0 TABLETEACH_PORT=8000
EXPOSE 8000
HEALTHCHECK --interval=10s --timeout=3s --retries=5 \
  CMD python -c "import urllib.request; urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=2)"
CMD ["tableteach", "serve"]
