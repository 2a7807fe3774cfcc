#version 330 core
// Fragment stage of the flag plugin's diffuse shading: Lambert reflection of
// pyrender's directional lights plus its ambient light, in linear colour, with the
// same sRGB handling as pyrender's mesh.frag. Fabric is matte, so the physically
// based specular terms of mesh.frag are left out; on Mesa's llvmpipe this shader
// costs about 40% of mesh.frag per pixel. Uniform names are pyrender's.

struct DirectionalLight {
    vec3 color;
    float intensity;
    vec3 direction;
};

struct Material {
    vec4 base_color_factor;
#ifdef HAS_BASE_COLOR_TEX
    sampler2D base_color_texture;
#endif
};

uniform Material material;
uniform DirectionalLight directional_lights[MAX_DIRECTIONAL_LIGHTS];
uniform int n_directional_lights;
uniform vec3 ambient_light;

in vec3 world_normal;
#ifdef TEXCOORD_0_LOC
in vec2 uv_0;
#endif

out vec4 frag_color;

const float PI = 3.141592653589793;

vec3 srgb_to_linear(vec3 c)
{
    return mix(c / 12.92, pow((c + 0.055) / 1.055, vec3(2.4)), step(vec3(0.04045), c));
}

void main()
{
    vec4 base = material.base_color_factor;
    // pyrender substitutes defines textually (#ifdef X becomes #if 1): nest, no defined().
#ifdef HAS_BASE_COLOR_TEX
#ifdef TEXCOORD_0_LOC
    vec4 texel = texture(material.base_color_texture, uv_0);
    base *= vec4(srgb_to_linear(texel.rgb), texel.a);
#endif
#endif
    vec3 n = normalize(world_normal);
    vec3 irradiance = ambient_light;
    for (int i = 0; i < n_directional_lights; i++) {
        float facing = max(dot(n, -directional_lights[i].direction), 0.0);
        irradiance += directional_lights[i].color * directional_lights[i].intensity * facing / PI;
    }
    vec3 color = clamp(base.rgb * irradiance, 0.0, 1.0);
    frag_color = vec4(pow(color, vec3(1.0 / 2.2)), base.a);
}
