// `loom render`'s framing: a camera fitted to a box (the whole sequence, not one frame), and a
// ground plane with the cloth's shadow on it (the cloth projected onto the plane along the
// light: a planar shadow, exact for a flat ground and a directional light).
#include <GLES3/gl3.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <glm/gtc/type_ptr.hpp>

#include "gl_renderer.hpp"

namespace loom::render {

namespace {

// One program for the ground (its quad lies on the plane, so the projection leaves it in
// place; lift 0, lit) and the shadow (the cloth's vertices projected along the light and
// lifted a little off the plane; ambient light only).
const char* kGroundVertex = R"(#version 300 es
uniform mat4 u_view_proj;
uniform vec3 u_point;
uniform vec3 u_normal;
uniform vec3 u_light_dir;
uniform float u_lift;
layout(location = 0) in vec3 a_pos;
void main() {
  float h = dot(u_normal, a_pos - u_point);
  vec3 p = a_pos - (h / dot(u_normal, u_light_dir)) * u_light_dir + u_lift * u_normal;
  gl_Position = u_view_proj * vec4(p, 1.0);
}
)";

const char* kGroundFragment = R"(#version 300 es
precision highp float;
uniform vec3 u_normal;
uniform vec3 u_light_dir;
uniform vec3 u_light;
uniform vec3 u_ambient;
uniform vec3 u_albedo;
uniform float u_direct;
out vec4 o_color;
void main() {
  vec3 c = u_albedo * (u_ambient + u_direct * u_light * max(dot(u_normal, u_light_dir), 0.0));
  o_color = vec4(pow(clamp(c, 0.0, 1.0), vec3(1.0 / 2.2)), 1.0);
}
)";

GLuint compile(GLenum kind, const char* src) {
  const GLuint s = glCreateShader(kind);
  glShaderSource(s, 1, &src, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[2048];
    glGetShaderInfoLog(s, sizeof(log), nullptr, log);
    throw std::runtime_error(std::string("gl renderer: ground shader failed to compile (a bug in Loom):\n") + log);
  }
  return s;
}

}  // namespace

void GlRenderer::update_light() {
  light_dir_ = light_direction(settings_.light, camera_);
  // With a ground and no light given, raise the default key light (which comes from beside the
  // camera) towards the ground's normal, so that the cloth casts a visible shadow.
  if (ground_ && !settings_.light.has_direction) light_dir_ = glm::normalize(light_dir_ + ground_normal_);
}

void GlRenderer::fit_camera(glm::vec3 lo, glm::vec3 hi) {
  if (!begun_) throw std::logic_error("gl renderer: fit_camera() before begin()");
  make_current();
  camera_ = make_camera(settings_.camera, lo, hi, settings_.width, settings_.height);
  update_light();
  set_uniforms();
}

void GlRenderer::set_ground(glm::vec3 point, glm::vec3 normal, float half_size) {
  if (!begun_) throw std::logic_error("gl renderer: set_ground() before begin()");
  if (!(glm::length(normal) > 0.0f) || !(half_size > 0.0f))
    throw std::logic_error("gl renderer: set_ground() needs a non-zero normal and size");
  make_current();
  ground_ = true;
  ground_point_ = point;
  ground_normal_ = glm::normalize(normal);
  ground_size_ = half_size;
  if (!ground_program_) {
    const GLuint vs = compile(GL_VERTEX_SHADER, kGroundVertex), fs = compile(GL_FRAGMENT_SHADER, kGroundFragment);
    ground_program_ = glCreateProgram();
    glAttachShader(ground_program_, vs);
    glAttachShader(ground_program_, fs);
    glLinkProgram(ground_program_);
    glDeleteShader(vs);
    glDeleteShader(fs);
    GLint linked = 0;
    glGetProgramiv(ground_program_, GL_LINK_STATUS, &linked);
    if (!linked) throw std::runtime_error("gl renderer: ground program link failed (a bug in Loom)");
    glGenVertexArrays(1, &ground_vao_);
    glGenBuffers(1, &ground_vbo_);
  }
  // The square [-s, s]^2 on the plane around the point, as two triangles.
  const glm::vec3 n = ground_normal_;
  const glm::vec3 a = glm::normalize(std::abs(n.x) < 0.9f ? glm::cross(n, glm::vec3(1, 0, 0)) : glm::cross(n, glm::vec3(0, 1, 0)));
  const glm::vec3 b = glm::cross(n, a);
  const glm::vec3 c[4] = {point + half_size * (-a - b), point + half_size * (a - b), point + half_size * (a + b),
                          point + half_size * (-a + b)};
  const glm::vec3 quad[6] = {c[0], c[1], c[2], c[0], c[2], c[3]};
  glBindVertexArray(ground_vao_);
  glBindBuffer(GL_ARRAY_BUFFER, ground_vbo_);
  glBufferData(GL_ARRAY_BUFFER, sizeof(quad), glm::value_ptr(quad[0]), GL_STATIC_DRAW);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 0, nullptr);
  glEnableVertexAttribArray(0);
  glBindVertexArray(0);
  update_light();
  set_uniforms();
}

void GlRenderer::draw_ground() {
  if (!ground_) return;
  glUseProgram(ground_program_);
  auto loc = [&](const char* name) { return glGetUniformLocation(ground_program_, name); };
  const glm::mat4 vp = camera_.proj * camera_.view;
  glUniformMatrix4fv(loc("u_view_proj"), 1, GL_FALSE, glm::value_ptr(vp));
  glUniform3fv(loc("u_point"), 1, glm::value_ptr(ground_point_));
  glUniform3fv(loc("u_normal"), 1, glm::value_ptr(ground_normal_));
  glUniform3fv(loc("u_light_dir"), 1, glm::value_ptr(light_dir_));
  const glm::vec3 light = settings_.light.color * settings_.light.intensity;
  const glm::vec3 ambient = settings_.light.color * settings_.light.ambient;
  glUniform3fv(loc("u_light"), 1, glm::value_ptr(light));
  glUniform3fv(loc("u_ambient"), 1, glm::value_ptr(ambient));
  glUniform3fv(loc("u_albedo"), 1, glm::value_ptr(kGroundAlbedo));
  // The ground, lit.
  glUniform1f(loc("u_lift"), 0.0f);
  glUniform1f(loc("u_direct"), 1.0f);
  glBindVertexArray(ground_vao_);
  glDrawArrays(GL_TRIANGLES, 0, 6);
  // The shadow: the cloth's triangles projected along the light, lifted off the plane by a
  // thousandth of the ground's size (and a polygon offset) so that they win the depth test.
  if (glm::dot(ground_normal_, light_dir_) > 0.05f) {
    glUniform1f(loc("u_lift"), 1e-3f * ground_size_);
    glUniform1f(loc("u_direct"), 0.0f);
    glEnable(GL_POLYGON_OFFSET_FILL);
    glPolygonOffset(-1.0f, -1.0f);
    glBindVertexArray(vao_);
    glDrawElements(GL_TRIANGLES, GLsizei(triangles_.size()), GL_UNSIGNED_INT, nullptr);
    glDisable(GL_POLYGON_OFFSET_FILL);
  }
  glBindVertexArray(0);
}

}  // namespace loom::render
