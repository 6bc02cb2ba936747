// Woven-fabric shading after Kang & Cho 2011, section 4 (see docs/RENDERING.md).
//
// ONE source for the GPU and the CPU: this file is compiled as GLSL ES 3.00 by the `gl`
// renderer plugin (which prepends "#define LOOM_SFN") and as C++ with glm by
// loom/kernels/shading.hpp (LOOM_SFN = inline LOOM_HD), so the CPU reference that the
// unit tests and the golden-image test use is the very math the fragment shader runs.
// Rules that keep it valid in both languages: float only, literals with an f suffix,
// single-component swizzles only, no out/inout parameters, structs filled member by
// member, no integer arithmetic, no GLSL-only or C++-only built-ins.
//
// Conventions. Tangent space of the surface: x = dP/du (the weft direction), y = the
// in-plane direction orthogonal to it (the warp direction), z = the geometric normal.
// l and v point away from the surface (towards the light and the viewer) and are unit.

const float LOOM_PI = 3.14159265358979f;

// Shading modes (Fabric.mode).
const float LOOM_MODE_FLAT = 0.0f;           // no normal perturbation
const float LOOM_MODE_NORMAL_MAP = 1.0f;     // perturbed normal, MDF axes left as they were
const float LOOM_MODE_ROTATE_EXACT = 2.0f;   // MDF rotated onto the perturbed normal, orthonormal frame
const float LOOM_MODE_ROTATE_PAPER = 3.0f;   // MDF rotated with the paper's eq. 17 frame (unnormalised)

// MDF kinds (Fabric.mdf).
const float LOOM_MDF_WARD = 0.0f;
const float LOOM_MDF_ASHIKHMIN = 1.0f;

struct Fabric {
  float n_w;              // continuous weft elements in a weave row
  float n_pi;             // continuous warp elements after them
  float n_sigma;          // element shift from one weave row to the next
  float density_u;        // weave elements per unit of u
  float density_v;        // weave elements per unit of v
  float yarn_curvature;   // c_y (eq. 13)
  float fibre_curvature;  // c_f
  float fibre_slope;      // s_f = 2 theta_f / pi
  float twists;           // N: fibre twists per weave element; 0 = filament yarn (no twist term)
  float mdf;              // LOOM_MDF_WARD or LOOM_MDF_ASHIKHMIN
  float alpha_along;      // MDF roughness along the fibres (Ward alpha; Ashikhmin n = 2/alpha^2 - 2)
  float alpha_across;     // MDF roughness across the fibres
  float mode;             // LOOM_MODE_*
  vec3 weft_color;        // diffuse albedo of weft yarns (linear RGB)
  vec3 warp_color;        // diffuse albedo of warp yarns
  vec3 specular;          // Fresnel reflectance at normal incidence (Schlick)
};

// ---- weave pattern (section 4.2) ----------------------------------------------------------

// 1 for a warp element, 0 for a weft element, at integer element indices (i, j): row j holds
// n_w weft elements then n_pi warp elements, repeating, shifted by n_sigma per row:
// warp iff mod(i - n_sigma j, n_w + n_pi) >= n_w.
// (The +0.5 keeps x / period away from whole numbers, so a GPU division that is not correctly
// rounded cannot push floor() to the wrong side; k is then a whole number +- rounding.)
LOOM_SFN float weave_is_warp(float i, float j, float n_w, float n_pi, float n_sigma) {
  float period = n_w + n_pi;
  float k = mod(i - n_sigma * j + 0.5f, period) - 0.5f;
  return k < n_w - 0.5f ? 0.0f : 1.0f;
}

// Fibre-twist term of eq. 13: c_f (2 fract(N (a - s_f sigma)) - 1), where a in [0, 1) runs
// along the yarn inside the element and sigma in [-1, 1) across it. Zero for N = 0.
LOOM_SFN float fibre_twist_term(float along, float sigma_across, float twists, float slope, float curvature) {
  if (twists <= 0.0f) return 0.0f;
  return curvature * (2.0f * fract(twists * (along - slope * sigma_across)) - 1.0f);
}

// Perturbed tangent-space normal of eq. 13 at element-local coordinates (fu, fv) in [0, 1)^2
// (sigma^u = 2 fu - 1, sigma^v = 2 fv - 1):
//   weft: (c_f (2 fract(N (fu - s_f sigma^v)) - 1), c_y sigma^v)
//   warp: (c_y sigma^u, c_f (2 fract(N (fv - s_f sigma^u)) - 1))
// z = sqrt(1 - x^2 - y^2). The twist phase uses the offset ACROSS the yarn (see RENDERING.md).
LOOM_SFN vec3 perturbed_normal(float warp, float fu, float fv, float yarn_curvature, float twists,
                               float slope, float fibre_curvature) {
  float su = 2.0f * fu - 1.0f;
  float sv = 2.0f * fv - 1.0f;
  float nx = 0.0f;
  float ny = 0.0f;
  if (warp > 0.5f) {
    nx = yarn_curvature * su;
    ny = fibre_twist_term(fv, su, twists, slope, fibre_curvature);
  } else {
    nx = fibre_twist_term(fu, sv, twists, slope, fibre_curvature);
    ny = yarn_curvature * sv;
  }
  return vec3(nx, ny, sqrt(max(1.0f - nx * nx - ny * ny, 0.0f)));
}

// ---- MDF rotation (section 4.3) -----------------------------------------------------------

// Eq. 19: h~ = R~^T h with the paper's frame u' = (0,1,0) x n~, v' = n~ x u', w' = n~ (eq. 17).
// u' and v' are orthogonal but both of length sqrt(1 - n~_y^2).
LOOM_SFN vec3 rotate_half_paper(vec3 h, vec3 n) {
  return vec3(n.z * h.x - n.x * h.z,
              -n.x * n.y * h.x + (1.0f - n.y * n.y) * h.y - n.y * n.z * h.z,
              n.x * h.x + n.y * h.y + n.z * h.z);
}

// The same frame normalised: R^T with orthonormal rows, so |h~| = |h| and R^T n~ = (0,0,1).
LOOM_SFN vec3 rotate_half_exact(vec3 h, vec3 n) {
  vec3 p = rotate_half_paper(h, n);
  float s = inversesqrt(max(1.0f - n.y * n.y, 1.0e-12f));
  return vec3(p.x * s, p.y * s, p.z);
}

// ---- microfacet distributions ------------------------------------------------------------
// Both take the half vector's components in the MDF's frame (x, y along the anisotropy
// axes, z along the normal) and use only cos(theta) = h.z and the azimuth of (h.x, h.y), so a
// uniform scale of the x, y components (eq. 17's unnormalised axes) does not change them.
// Both are normalised over the projected hemisphere: integral of D(h) cos(theta_h) = 1.

// Anisotropic Ward (elliptical Beckmann): exp(-tan^2(theta) (cos^2 phi/ax^2 + sin^2 phi/ay^2)) / (pi ax ay cos^4 theta).
LOOM_SFN float ward_mdf(vec3 h, float ax, float ay) {
  float c = h.z;
  if (c <= 0.0f) return 0.0f;
  float c2 = c * c;
  float r2 = h.x * h.x + h.y * h.y;
  float e = 0.0f;
  if (r2 > 0.0f) e = (h.x * h.x / (ax * ax) + h.y * h.y / (ay * ay)) / r2 * max(1.0f - c2, 0.0f) / c2;
  return exp(-e) / (LOOM_PI * ax * ay * c2 * c2);
}

// Ashikhmin-Shirley: sqrt((nu+2)(nv+2)) / (2 pi) cos(theta)^(nu cos^2 phi + nv sin^2 phi).
// (The paper's constant sqrt((nu+1)(nv+1))/(2 pi) normalises D itself; +2 normalises D cos.)
LOOM_SFN float ashikhmin_mdf(vec3 h, float nu, float nv) {
  float c = h.z;
  if (c <= 0.0f) return 0.0f;
  float r2 = h.x * h.x + h.y * h.y;
  float e = 0.5f * (nu + nv);
  if (r2 > 0.0f) e = (nu * h.x * h.x + nv * h.y * h.y) / r2;
  return sqrt((nu + 2.0f) * (nv + 2.0f)) / (2.0f * LOOM_PI) * pow(min(c, 1.0f), e);
}

// Ashikhmin-Shirley exponent with the same lobe width as a Beckmann/Ward alpha.
LOOM_SFN float ashikhmin_exponent(float alpha) { return 2.0f / (alpha * alpha) - 2.0f; }

// MDF of the fabric with x = the weft direction: weft fibres run along x, warp fibres along y.
LOOM_SFN float fabric_mdf(vec3 h, float warp, Fabric f) {
  float ax = f.alpha_along;
  float ay = f.alpha_across;
  if (warp > 0.5f) {
    ax = f.alpha_across;
    ay = f.alpha_along;
  }
  if (f.mdf > 0.5f) return ashikhmin_mdf(h, ashikhmin_exponent(ax), ashikhmin_exponent(ay));
  return ward_mdf(h, ax, ay);
}

// Half vector in the frame the MDF is evaluated in, for normal n (tangent space) and mode.
LOOM_SFN vec3 mdf_half_vector(vec3 h, vec3 n, float mode) {
  if (mode > 2.5f) return rotate_half_paper(h, n);
  if (mode > 1.5f) return rotate_half_exact(h, n);
  if (mode > 0.5f) return vec3(h.x, h.y, dot(h, n));  // normal mapping: only the normal moves
  return h;
}

// ---- the BRDF ----------------------------------------------------------------------------

// Outgoing linear radiance at texture coordinates uv for unit tangent-space l and v.
// light: radiance scale of the directional light such that a white Lambertian surface facing
// it shows `light`; ambient: added as ambient * albedo.
//   L = ambient albedo + light (albedo (n.l) + pi D F / (4 max(n.l, n.v)) (n.l))
// with n the perturbed normal (flat mode: the geometric one) and F Schlick's Fresnel.
LOOM_SFN vec3 shade_fabric(Fabric f, vec2 uv, vec3 l, vec3 v, vec3 light, vec3 ambient) {
  float cu = uv.x * f.density_u;
  float cv = uv.y * f.density_v;
  float i = floor(cu);
  float j = floor(cv);
  float warp = weave_is_warp(i, j, f.n_w, f.n_pi, f.n_sigma);
  vec3 n = vec3(0.0f, 0.0f, 1.0f);
  if (f.mode > 0.5f)
    n = perturbed_normal(warp, cu - i, cv - j, f.yarn_curvature, f.twists, f.fibre_slope, f.fibre_curvature);
  vec3 albedo = mix(f.weft_color, f.warp_color, warp);
  vec3 color = ambient * albedo;
  float nl = dot(n, l);
  float nv = dot(n, v);
  if (l.z <= 0.0f || nl <= 0.0f) return color;
  color = color + light * albedo * nl;
  if (nv <= 0.0f) return color;
  vec3 h = normalize(l + v);
  float d = fabric_mdf(mdf_half_vector(h, n, f.mode), warp, f);
  float vh = max(dot(v, h), 0.0f);
  float m = 1.0f - vh;
  float m5 = m * m * m * m * m;
  vec3 fresnel = f.specular + (vec3(1.0f) - f.specular) * m5;
  return color + light * fresnel * (LOOM_PI * d * nl / (4.0f * max(nl, nv)));
}

// Shade in world space: n_geo and t_geo are the interpolated vertex normal and tangent
// (dP/du), v_world and l_world unit vectors towards the viewer and the light. Cloth is
// two-sided: when the viewer is behind the normal, the frame is flipped (n -> -n, and the
// bitangent with it so the frame stays right-handed).
LOOM_SFN vec3 shade_world(Fabric f, vec2 uv, vec3 n_geo, vec3 t_geo, vec3 v_world, vec3 l_world,
                          vec3 light, vec3 ambient) {
  vec3 n = normalize(n_geo);
  if (dot(n, v_world) < 0.0f) n = -n;
  vec3 t = t_geo - n * dot(n, t_geo);
  float tl = dot(t, t);
  if (tl < 1.0e-20f) {
    // No usable tangent (degenerate UVs): any direction orthogonal to n.
    t = abs(n.x) < 0.9f ? vec3(1.0f, 0.0f, 0.0f) : vec3(0.0f, 1.0f, 0.0f);
    t = t - n * dot(n, t);
    tl = dot(t, t);
  }
  t = t * inversesqrt(tl);
  vec3 b = cross(n, t);
  vec3 l = vec3(dot(l_world, t), dot(l_world, b), dot(l_world, n));
  vec3 v = vec3(dot(v_world, t), dot(v_world, b), dot(v_world, n));
  return shade_fabric(f, uv, l, v, light, ambient);
}

// Display transform: exposure, clamp to [0, 1], gamma 2.2.
LOOM_SFN vec3 display_color(vec3 c, float exposure) {
  vec3 e = clamp(c * exposure, vec3(0.0f), vec3(1.0f));
  return vec3(pow(e.x, 1.0f / 2.2f), pow(e.y, 1.0f / 2.2f), pow(e.z, 1.0f / 2.2f));
}
