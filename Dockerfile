# Terrabound container: a build stage that builds and runs the tests with the same setup script
# CI uses, and a slim runtime stage with the binary, its runtime libraries and config/.
#   docker build -t terrabound .
#   docker run -p 8080:8080 -v /path/to/dems:/data terrabound serve /data/dem.tif --host 0.0.0.0
FROM debian:12 AS build
RUN apt-get update -qq && apt-get install -y -qq --no-install-recommends \
        make sudo ca-certificates nodejs npm && rm -rf /var/lib/apt/lists/*
WORKDIR /src
COPY . .
RUN scripts/setup.sh && make test && make build

FROM debian:12-slim AS runtime
COPY scripts/setup.sh /tmp/setup.sh
RUN /tmp/setup.sh --runtime && rm -rf /var/lib/apt/lists/* /tmp/setup.sh \
    && useradd --system --home /var/lib/terrabound --create-home terrabound \
    && mkdir -p /var/lib/terrabound/data && chown terrabound /var/lib/terrabound
COPY --from=build /src/build/terrabound /usr/local/bin/terrabound
COPY --from=build /src/config /etc/terrabound
COPY --from=build /src/data/N57E011.hgt /var/lib/terrabound/data/N57E011.hgt
# The viewer at /: its page and the two npm packages it loads (found beside the binary).
COPY --from=build /src/web/index.html /src/web/viewer.js /src/web/viewer.css /usr/local/share/terrabound/web/
COPY --from=build /src/web/node_modules/cesium/Build /usr/local/share/terrabound/web/node_modules/cesium/Build
COPY --from=build /src/web/node_modules/three /usr/local/share/terrabound/web/node_modules/three
USER terrabound
WORKDIR /var/lib/terrabound
EXPOSE 8080
HEALTHCHECK --interval=30s --timeout=3s --start-period=10s \
    CMD curl -fsS http://127.0.0.1:8080/health || exit 1
ENTRYPOINT ["terrabound"]
CMD ["serve", "/etc/terrabound/docker.json"]
