// The API docs page (/v1/docs): Swagger UI (swagger-ui-dist, Apache-2.0, vendored beside this
// file) on the service's own OpenAPI document. A file, not an inline script: the page's
// Content-Security-Policy allows the service's own scripts only.
window.ui = SwaggerUIBundle({
  url: "/v1/openapi.json",
  dom_id: "#swagger-ui",
  deepLinking: true,
  presets: [SwaggerUIBundle.presets.apis],
  layout: "BaseLayout",
});
