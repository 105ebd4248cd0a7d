# One image for every augnet service; the compose file picks the command.
FROM python:3.11-slim-bookworm
RUN apt-get update && apt-get install -y --no-install-recommends rtklib curl \
    && rm -rf /var/lib/apt/lists/*
WORKDIR /app
COPY pyproject.toml README.md ./
COPY augnet ./augnet
COPY augwire ./augwire
COPY stations ./stations
COPY ntrip_caster ./ntrip_caster
COPY rssp1 ./rssp1
RUN pip install --no-cache-dir .
EXPOSE 2101 8000
ENTRYPOINT ["augnet"]
