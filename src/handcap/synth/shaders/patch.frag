// Fragment shader of handcap.synth.images: printed patch (atlas) or skin, procedural grain, two lights,
// Lambert shading and Blinn-Phong glints, one grey channel.
#version 330
uniform sampler2D atlas;
uniform int textured;        // 1: printed patch, 0: skin or occluder
uniform float albedo;        // base reflectance of skin / occluder
uniform float grain;         // strength of the surface's procedural texture
uniform float grain_scale;   // metres per texture cell
uniform vec3 eye;
uniform vec3 light_dir[2];
uniform float light_power[2];
uniform float ambient;
uniform float shininess;
uniform float specular;
in vec3 v_pos;
in vec3 v_normal;
in vec2 v_uv;
out vec4 colour;
float hash(vec3 p) {
    p = fract(p * 0.3183099 + vec3(0.71, 0.113, 0.419));
    p *= 17.0;
    return fract(p.x * p.y * p.z * (p.x + p.y + p.z));
}
float noise(vec3 x) {
    vec3 i = floor(x);
    vec3 f = fract(x);
    f = f * f * (3.0 - 2.0 * f);
    float a = mix(mix(hash(i), hash(i + vec3(1, 0, 0)), f.x),
                  mix(hash(i + vec3(0, 1, 0)), hash(i + vec3(1, 1, 0)), f.x), f.y);
    float b = mix(mix(hash(i + vec3(0, 0, 1)), hash(i + vec3(1, 0, 1)), f.x),
                  mix(hash(i + vec3(0, 1, 1)), hash(i + vec3(1, 1, 1)), f.x), f.y);
    return mix(a, b, f.z);
}
void main() {
    vec3 n = normalize(v_normal);
    vec3 view = normalize(eye - v_pos);
    if (dot(n, view) < 0.0) n = -n;
    float base;
    float tex = noise(v_pos / grain_scale) * 0.6 + noise(v_pos / (0.27 * grain_scale)) * 0.4;
    if (textured == 1) {
        float ink = texture(atlas, v_uv).r;
        base = mix(0.05, 0.88, ink) * (1.0 + grain * (tex - 0.5));
    } else {
        base = albedo * (1.0 + grain * (tex - 0.5));
    }
    float shade = ambient;
    float shine = 0.0;
    for (int k = 0; k < 2; k++) {
        vec3 l = normalize(light_dir[k]);
        shade += light_power[k] * max(dot(n, l), 0.0);
        vec3 h = normalize(l + view);
        shine += light_power[k] * pow(max(dot(n, h), 0.0), shininess);
    }
    colour = vec4(vec3(base * shade + specular * shine), 1.0);
}
