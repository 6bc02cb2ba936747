// CPU build of the woven-fabric shading math (Kang & Cho 2011, section 4).
//
// The math lives in shading.glsl, written in the common subset of GLSL ES 3.00 and C++/glm:
// the `gl` renderer compiles that file into its fragment shader, and this header compiles the
// same text as C++ (float, glm vectors), so the unit tests and the golden-image reference run
// exactly what the GPU runs. Functions are inline and LOOM_HD (host+device).
//
//   loom::shading::Fabric f = ...;                       // see shading.glsl for the fields
//   glm::vec3 rgb = loom::shading::shade_fabric(f, uv, l, v, light, ambient);
#pragma once

#include <glm/glm.hpp>

#include "loom/common.hpp"

namespace loom::shading {

using glm::vec2;
using glm::vec3;
using glm::abs;
using glm::clamp;
using glm::cross;
using glm::dot;
using glm::exp;
using glm::floor;
using glm::fract;
using glm::inversesqrt;
using glm::max;
using glm::min;
using glm::mix;
using glm::mod;
using glm::normalize;
using glm::pow;
using glm::sqrt;

#define LOOM_SFN inline LOOM_HD
#include "loom/kernels/shading.glsl"
#undef LOOM_SFN

}  // namespace loom::shading
