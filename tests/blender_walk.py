"""What the export does with each of Blender's render-related settings: the classification that
``tests/test_blender_walk.py`` holds against Blender's own RNA.

Every property of the walked structs and every shader node type is one of:

- ``M`` modeled: read (or evaluated by Blender's depsgraph before the export reads the result),
  with the test that checks it (``file.py::test``);
- ``W`` warned: not modeled, and the export says so (the warning's words, as they stand in the
  add-on's source);
- ``I`` irrelevant to the image: with the reason.

The walk runs on the newest and on the oldest supported Blender, so a name that only one of them
has is listed too.  Only this module and the test use it (no ``bpy`` needed to import it).
"""
from __future__ import annotations

# ------------------------------------------------------------------ shared reasons
ID = "data-block bookkeeping (names, users, library, tags, previews)"
ANIM = "animation: the depsgraph hands the export the evaluated values of the current frame"
UI = "viewport and editor display only"
EEVEE = "EEVEE or Workbench only; Cycles does not read it"
PHYSICS = "simulation settings: the depsgraph hands the export the evaluated result"
OUTPUT = "file output, metadata or the compositor: not the rendered radiance"
SAMPLING = "how Cycles samples (noise and speed); raybundle has its own estimators"
PASSES = "render passes other than Combined: raybundle renders the Combined pass"
DEVICE = "device, threads, memory or debugging: not the image"
DEPSGRAPH = "evaluated by Blender's depsgraph: the export reads the evaluated geometry and matrix_world"

T_EXPORT = "test_addon_export.py::"
T_RENDER = "test_addon_render.py::"
T_LIGHTS = "test_addon_light_settings.py::"

_ID_PROPS = ("name name_full id_type session_uid deep_hash is_evaluated original users use_fake_user use_extra_user "
             "is_embedded_data is_linked_packed is_missing is_runtime_data is_editable tag is_library_indirect "
             "library library_weak_reference asset_data override_library preview").split()


def _many(names, cls):
    return {n: cls for n in names.split()}


def _id(extra=None):
    out = {n: ("I", ID) for n in _ID_PROPS}
    out["animation_data"] = ("I", ANIM)
    out.update(extra or {})
    return out


OBJECT = _id({
    **_many("data type parent parent_type parent_vertices parent_bone parent_bone_head_tail_factor "
            "use_parent_final_indices use_camera_lock_parent track_axis up_axis location rotation_quaternion "
            "rotation_axis_angle rotation_euler rotation_mode scale dimensions delta_location delta_rotation_euler "
            "delta_rotation_quaternion delta_scale matrix_world matrix_local matrix_basis matrix_parent_inverse "
            "constraints vertex_groups pose active_shape_key active_shape_key_index show_only_shape_key "
            "add_rest_position_attribute",
            ("M", T_EXPORT + "test_modifiers_are_applied")),
    "modifiers": ("M", T_EXPORT + "test_modifiers_are_applied"),
    **_many("instance_type use_instance_vertices_rotation use_instance_faces_scale instance_faces_scale "
            "instance_collection is_instancer show_instancer_for_render is_from_instancer",
            ("M", T_EXPORT + "test_collection_instances_ngon_and_missing_material")),
    "particle_systems": ("M", T_EXPORT + "test_particle_and_geometry_node_instances"),
    **_many("material_slots active_material active_material_index hide_render",
            ("M", T_EXPORT + "test_material_slots_and_hidden_objects")),
    "light_linking": ("M", T_LIGHTS + "test_light_and_shadow_linking_on_lamps_as_in_cycles"),
    **_many("visible_camera visible_diffuse visible_glossy visible_transmission visible_volume_scatter visible_shadow",
            ("W", "per-ray-type visibility is not supported")),
    **_many("is_holdout is_shadow_catcher", ("W", "holdout / shadow catcher is not supported")),
    **_many("shadow_terminator_normal_offset shadow_terminator_shading_offset",
            ("W", "shadow terminator normal and shading offsets are not modeled")),
    "shadow_terminator_geometry_offset": ("M", T_EXPORT + "test_the_shadow_terminator_geometry_offset_is_exported_per_object"),
    **_many("mode bound_box hide_viewport hide_select hide_surface_pick show_instancer_for_viewport display_type "
            "show_bounds display_bounds_type show_name show_axis show_texture_space show_wire show_all_edges "
            "show_transparent show_in_front empty_display_type empty_display_size empty_image_offset image_user "
            "empty_image_depth show_empty_image_perspective show_empty_image_orthographic "
            "show_empty_image_only_axis_aligned use_empty_image_alpha empty_image_side use_shape_key_edit_mode "
            "use_dynamic_topology_sculpting display use_mesh_mirror_x use_mesh_mirror_y use_mesh_mirror_z "
            "animation_visualization motion_path selection_sets active_selection_set is_from_set "
            "use_grease_pencil_lights shader_effects lineart lock_location lock_rotation lock_rotation_w "
            "lock_rotations_4d lock_scale grease_pencil_modifiers", ("I", UI)),
    **_many("hide_probe_volume hide_probe_sphere hide_probe_plane visible_raycast", ("I", EEVEE)),
    **_many("field collision soft_body rigid_body rigid_body_constraint use_simulation_cache", ("I", PHYSICS)),
    "pass_index": ("I", PASSES),
    "lightgroup": ("I", PASSES),
    "color": ("I", "the Object Info node's Color; a material reading it is warned as an unevaluated graph"),
    "cycles": ("I", "a group: walked on its own (Object.cycles)"),
})

OBJECT_CYCLES = {
    "name": ("I", ID),
    **_many("use_motion_blur use_deform_motion motion_steps", ("W", "motion blur is not supported")),
    **_many("use_camera_cull use_distance_cull", ("W", "culling is not modeled")),
    "shadow_terminator_offset": ("W", "shadow terminator normal and shading offsets are not modeled"),
    "shadow_terminator_geometry_offset": ("M", T_EXPORT + "test_the_shadow_terminator_geometry_offset_is_exported_per_object"),
    "ao_distance": ("I", "Fast GI's ambient occlusion distance, used only with Fast GI (warned on the scene)"),
    **_many("is_caustics_caster is_caustics_receiver", ("I", SAMPLING + " (Cycles' manifold next event "
                                                               "estimation)")),
    **_many("use_adaptive_subdivision dicing_rate",
            ("I", "adaptive subdivision (experimental feature set): the depsgraph's mesh is exported")),
}

LIGHT = _id({
    **_many("type color energy exposure normalize shadow_soft_size shape size size_y",
            ("M", T_EXPORT + "test_light_units")),
    **_many("use_temperature temperature temperature_color", ("M", T_EXPORT + "test_light_temperature_and_unnormalized")),
    "use_shadow": ("M", T_LIGHTS + "test_cast_shadow_off_lets_the_lamp_light_through_the_block_as_in_cycles"),
    **_many("node_tree use_nodes", ("M", T_LIGHTS + "test_a_lights_node_tree_scales_its_emission_as_in_cycles")),
    "spread": ("W", "spread is not modelled"),
    "use_soft_falloff": ("W", "soft falloff is not modelled"),
    **_many("spot_size spot_blend", ("M", "test_blender_semantics.py::test_spot_light_cone_and_blend_match_cycles_formula")),
    **_many("show_cone use_square", ("I", EEVEE)),
    "angle": ("M", T_EXPORT + "test_light_units"),
    **_many("specular_factor diffuse_factor transmission_factor volume_factor use_custom_distance cutoff_distance "
            "shadow_buffer_clip_start shadow_filter_radius "
            "shadow_maximum_resolution use_shadow_jitter shadow_jitter_overblur use_absolute_resolution "
            "shadow_buffer_bias contact_shadow_distance contact_shadow_thickness contact_shadow_bias "
            "use_contact_shadow shadow_cascade_count shadow_cascade_max_distance shadow_cascade_exponent "
            "shadow_cascade_fade shadow_color", ("I", EEVEE)),
    "cycles": ("I", "a group: walked on its own (Light.cycles)"),
})

LIGHT_CYCLES = {
    "name": ("I", ID),
    "is_portal": ("M", T_EXPORT + "test_material_override_and_portals"),
    "max_bounces": ("W", "its max bounces"),
    **_many("use_multiple_importance_sampling is_caustics_light", ("I", SAMPLING)),
}

CAMERA = _id({
    **_many("type sensor_fit lens lens_unit sensor_width sensor_height shift_x shift_y ortho_scale clip_start angle "
            "angle_x angle_y", ("M", T_EXPORT + "test_camera_resolution_border_and_ortho")),
    "clip_end": ("W", "(clip end is not modelled)"),
    "dof": ("W", "depth of field is not supported"),
    **_many("panorama_type fisheye_fov fisheye_lens latitude_min latitude_max longitude_min longitude_max "
            "fisheye_polynomial_k0 fisheye_polynomial_k1 fisheye_polynomial_k2 fisheye_polynomial_k3 "
            "fisheye_polynomial_k4 central_cylindrical_range_u_min central_cylindrical_range_u_max "
            "central_cylindrical_range_v_min central_cylindrical_range_v_max central_cylindrical_radius "
            "custom_filepath custom_shader custom_mode custom_bytecode custom_bytecode_hash cycles_custom",
            ("I", "panoramic and custom cameras only, which are refused with an error")),
    "stereo": ("W", "multi-view (stereo) is not supported"),
    **_many("passepartout_alpha display_size show_limits show_mist show_passepartout show_safe_areas show_safe_center "
            "show_name show_sensor show_background_images composition_guide_color show_composition_center "
            "show_composition_center_diagonal show_composition_thirds show_composition_golden "
            "show_composition_golden_tria_a show_composition_golden_tria_b show_composition_harmony_tri_a "
            "show_composition_harmony_tri_b background_images", ("I", UI)),
})

CAMERA_DOF = {n: ("W", "depth of field is not supported") for n in
              "use_dof focus_object focus_subtarget focus_distance aperture_fstop aperture_blades aperture_rotation "
              "aperture_ratio".split()}

WORLD = _id({
    **_many("node_tree use_nodes color", ("M", T_EXPORT + "test_world_is_evaluated_by_blender_in_the_cores_layout")),
    "cycles_visibility": ("W", "world ray visibility is not modeled"),
    "light_settings": ("I", "Fast GI's ambient occlusion (Fast GI is warned on the scene)"),
    "mist_settings": ("I", PASSES),
    "lightgroup": ("I", PASSES),
    **_many("use_eevee_finite_volume probe_resolution sun_threshold sun_angle use_sun_shadow "
            "sun_shadow_maximum_resolution sun_shadow_filter_radius use_sun_shadow_jitter "
            "sun_shadow_jitter_overblur", ("I", EEVEE)),
    "cycles": ("I", "a group: walked on its own (World.cycles)"),
})

WORLD_CYCLES = {
    "name": ("I", ID),
    "use_shadows": ("W", "world shadows off is not modeled"),
    **_many("is_caustics_light sampling_method sample_map_resolution", ("I", SAMPLING)),
    "max_bounces": ("W", "its max bounces"),
    **_many("volume_sampling volume_interpolation volume_step_size homogeneous_volume",
            ("I", "the world's volume, which is warned")),
}

VIEW_LAYER = {
    "name": ("M", "test_addon_cli.py::test_cli_writes_each_view_layer_as_blender_renders_it"),
    "use": ("M", "test_addon_cli.py::test_cli_writes_each_view_layer_as_blender_renders_it"),
    "layer_collection": ("M", "test_addon_cli.py::test_cli_writes_each_view_layer_as_blender_renders_it"),
    **_many("objects depsgraph", ("I", DEPSGRAPH)),
    "material_override": ("M", T_EXPORT + "test_material_override_and_portals"),
    "world_override": ("M", T_EXPORT + "test_a_view_layers_world_override_is_its_world"),
    **_many("use_sky use_solid", ("W", "the view layer's filter")),
    **_many("use_ao", ("I", "Fast GI's ambient occlusion (Fast GI is warned on the scene)")),
    **_many("use_strand use_volumes use_motion_blur use_grease_pencil",
            ("I", "a filter of what raybundle does not render (hair, volumes and motion blur are warned; grease "
                  "pencil is drawn by Blender's own engine)")),
    "samples": ("I", SAMPLING),
    **_many("pass_alpha_threshold aovs active_aov active_aov_index lightgroups active_lightgroup "
            "active_lightgroup_index use_pass_cryptomatte_object use_pass_cryptomatte_material "
            "use_pass_cryptomatte_asset pass_cryptomatte_depth use_pass_cryptomatte_accurate use_pass_combined "
            "use_pass_z use_pass_vector use_pass_position use_pass_normal use_pass_uv use_pass_mist "
            "use_pass_object_index use_pass_material_index use_pass_shadow use_pass_ambient_occlusion use_pass_emit "
            "use_pass_environment use_pass_diffuse_direct use_pass_diffuse_indirect use_pass_diffuse_color "
            "use_pass_glossy_direct use_pass_glossy_indirect use_pass_glossy_color use_pass_transmission_direct "
            "use_pass_transmission_indirect use_pass_transmission_color use_pass_subsurface_direct "
            "use_pass_subsurface_indirect use_pass_subsurface_color use_pass_grease_pencil", ("I", PASSES)),
    **_many("eevee", ("I", EEVEE)),
    **_many("active_layer_collection has_export_collections", ("I", UI)),
    **_many("use_freestyle freestyle_settings", ("W", "Freestyle lines are not drawn")),
    "cycles": ("I", "a group: walked on its own (ViewLayer.cycles)"),
    "raybundle": ("M", "test_addon_components.py::test_light_components_sum_to_the_image_and_match_cycles_passes"),
}

VIEW_LAYER_CYCLES = {
    "name": ("I", ID),
    **_many("pass_debug_sample_count pass_render_time use_pass_volume_direct use_pass_volume_indirect "
            "use_pass_volume_scatter use_pass_volume_transmit use_pass_volume_majorant use_pass_shadow_catcher "
            "denoising_store_passes denoising_store_motion_passes", ("I", PASSES)),
    **_many("use_denoising denoising_pass_follow_reflections denoising_pass_use_albedo_roughness_weighting",
            ("I", "Cycles' denoiser of its own noise; raybundle's image is not denoised")),
}

RENDER = {
    **_many("resolution_x resolution_y resolution_percentage pixel_aspect_x pixel_aspect_y use_border border_min_x "
            "border_min_y border_max_x border_max_y use_crop_to_border",
            ("M", T_RENDER + "test_resolution_percentage_border_and_view_layers")),
    "use_single_layer": ("M", T_RENDER + "test_resolution_percentage_border_and_view_layers"),
    "engine": ("I", "which engine renders: RAYBUNDLE"),
    "film_transparent": ("W", "transparent film is not supported"),
    **_many("use_motion_blur motion_blur_shutter motion_blur_position motion_blur_shutter_curve",
            ("W", "motion blur is not supported")),
    **_many("use_simplify simplify_subdivision simplify_child_particles simplify_subdivision_render "
            "simplify_child_particles_render simplify_volumes use_simplify_normals", ("I", DEPSGRAPH)),
    **_many("simplify_gpencil simplify_gpencil_onplay simplify_gpencil_antialiasing simplify_gpencil_view_fill "
            "simplify_gpencil_modifier simplify_gpencil_shader_fx simplify_gpencil_tint",
            ("I", "grease pencil, drawn by Blender's own engine")),
    **_many("hair_type hair_subdiv", ("I", "hair strands, which are warned")),
    **_many("use_multiview views stereo_views views_format use_spherical_stereo",
            ("W", "multi-view (stereo) is not supported")),
    **_many("use_freestyle line_thickness_mode line_thickness", ("W", "Freestyle lines are not drawn")),
    **_many("fps fps_base frame_map_old frame_map_new", ("I", ANIM)),
    **_many("image_settings ffmpeg dither_intensity use_placeholder use_overwrite save_output use_compositing "
            "use_sequencer use_file_extension file_extension is_movie_format filepath use_render_cache "
            "use_stamp_time use_stamp_date use_stamp_frame use_stamp_frame_range use_stamp_camera use_stamp_lens "
            "use_stamp_scene use_stamp_note use_stamp_marker use_stamp_filename use_stamp_sequencer_strip "
            "use_stamp_render_time stamp_note_text use_stamp use_stamp_labels metadata_input use_stamp_memory "
            "use_stamp_hostname stamp_font_size stamp_foreground stamp_background "
            "use_sequencer_override_scene_strip compositor_device use_compositor_frames_cache compositor_precision "
            "compositor_denoise_device compositor_denoise_preview_quality compositor_denoise_final_quality "
            "use_stamp_frame_range", ("I", OUTPUT)),
    **_many("threads threads_mode use_persistent_data use_texture_cache use_auto_generate_texture_cache",
            ("I", DEVICE)),
    **_many("preview_pixel_size use_lock_interface sequencer_gl_preview has_multiple_engines ppm_factor ppm_base "
            "use_high_quality_normals anisotropic_filter", ("I", UI)),
    "filter_size": ("I", EEVEE + " (Cycles' pixel filter is Scene.cycles.filter_width)"),
    **_many("bake bake_bias bake_margin bake_margin_type bake_samples bake_type bake_user_scale use_bake_clear "
            "use_bake_lores_mesh use_bake_multires use_bake_selected_to_active use_bake_user_scale",
            ("I", "Blender's own bake settings; raybundle bakes from its panel")),
}

SCENE_CYCLES = {
    "name": ("I", ID),
    **_many("pixel_filter_type filter_width", ("M", T_RENDER + "test_the_pixel_filter_blurs_edges_as_cycles_does")),
    "film_exposure": ("W", "film exposure"),
    **_many("max_bounces diffuse_bounces glossy_bounces transmission_bounces transparent_max_bounces",
            ("W", "bounce limits")),
    **_many("sample_clamp_direct sample_clamp_indirect", ("W", "sample clamping")),
    **_many("caustics_reflective caustics_refractive", ("W", "caustics settings")),
    **_many("use_fast_gi fast_gi_method ao_bounces ao_bounces_render", ("W", "Fast GI")),
    **_many("use_camera_cull camera_cull_margin use_distance_cull distance_cull_margin",
            ("W", "culling is not modeled")),
    **_many("texture_limit texture_limit_render", ("W", "texture size limit")),
    **_many("film_transparent_glass film_transparent_roughness",
            ("I", "with a transparent film only, which is warned")),
    "blur_glossy": ("I", "Filter Glossy: Cycles blurs its own glossy paths against noise; raybundle does not"),
    **_many("rolling_shutter_type rolling_shutter_duration", ("I", "motion blur, which is warned")),
    **_many("volume_step_rate volume_preview_step_rate volume_max_steps volume_biased volume_bounces",
            ("I", "volumes, which are warned")),
    **_many("dicing_rate preview_dicing_rate max_subdivisions dicing_camera offscreen_dicing_scale",
            ("I", "adaptive subdivision (experimental feature set): the depsgraph's mesh is exported")),
    **_many("samples preview_samples use_sample_subset sample_offset sample_subset_length time_limit sampling_pattern "
            "scrambling_distance preview_scrambling_distance auto_scrambling_distance use_layer_samples "
            "light_sampling_threshold use_adaptive_sampling adaptive_threshold adaptive_min_samples "
            "use_preview_adaptive_sampling preview_adaptive_threshold preview_adaptive_min_samples "
            "direct_light_sampling_type use_light_tree min_light_bounces min_transparent_bounces use_guiding "
            "use_deterministic_guiding guiding_distribution_type guiding_directional_sampling_type "
            "use_surface_guiding surface_guiding_probability use_volume_guiding guiding_training_samples "
            "volume_guiding_probability use_guiding_direct_light use_guiding_mis_weights guiding_roughness_threshold "
            "seed use_animated_seed use_pixel_jitter", ("I", SAMPLING)),
    **_many("use_denoising denoiser denoising_prefilter denoising_quality denoising_input_passes denoising_use_gpu "
            "use_preview_denoising preview_denoiser preview_denoising_prefilter preview_denoising_quality "
            "preview_denoising_input_passes preview_denoising_start_sample preview_denoising_use_gpu "
            "preview_denoising_upscale_quality",
            ("I", "Cycles' denoiser of its own noise; raybundle's image is not denoised")),
    **_many("device shading_system preview_pause debug_bvh_type debug_use_spatial_splits debug_use_hair_bvh "
            "debug_use_compact_bvh debug_bvh_time_steps use_auto_tile tile_size debug_use_cpu_avx2 "
            "debug_use_cpu_sse42 debug_bvh_layout debug_use_cuda_adaptive_compile debug_use_optix_debug "
            "debug_use_hip_adaptive_compile debug_use_metal_adaptive_compile debug_use_texture_cache_eviction "
            "debug_texture_cache_preserve_unused texture_resolution texture_resolution_render debug_use_cpu_split_kernel "
            "debug_use_cpu_sse41 debug_use_cpu_sse3 debug_use_cpu_sse2", ("I", DEVICE)),
    "bake_type": ("I", "Blender's own bake settings; raybundle bakes from its panel"),
    "feature_set": ("I", "Cycles' experimental features (adaptive subdivision): the depsgraph's mesh is exported"),
}

VIEW_SETTINGS = {
    **_many("look view_transform exposure gamma curve_mapping use_curve_mapping use_white_balance "
            "white_balance_temperature white_balance_tint white_balance_whitepoint is_hdr support_emulation "
            "use_hdr_view",
            ("I", "colour management, applied by Blender to the linear image the engine writes")),
}

#: the structs walked: (label, how the test reaches it from an object, a light, the scene...)
STRUCTS = {
    "Object": OBJECT, "Object.cycles": OBJECT_CYCLES, "Light": LIGHT, "Light.cycles": LIGHT_CYCLES,
    "Camera": CAMERA, "Camera.dof": CAMERA_DOF, "World": WORLD, "World.cycles": WORLD_CYCLES,
    "ViewLayer": VIEW_LAYER, "ViewLayer.cycles": VIEW_LAYER_CYCLES, "RenderSettings": RENDER,
    "Scene.cycles": SCENE_CYCLES, "Scene.view_settings": VIEW_SETTINGS,
}

T_MATS = "test_addon_materials.py::"
_GRAPH = ("M", T_MATS + "test_a_node_driven_roughness_and_color_are_blenders_values")
_ON_OBJECT = ("M", T_MATS + "test_a_color_ramp_on_a_noise_texture_is_baked_on_the_object_as_cycles_renders_it")
_NOT_EVALUATED = ("W", "which depends on the view, the light or more than the point")
_UNSUPPORTED = ("W", "is not supported")
_VOLUME = ("W", "volume")

#: shader node types (``bpy.types`` names), as a material, light or world can hold them
NODES = {
    "ShaderNode": ("I", "the base class of shader nodes, not a node"),
    "ShaderNodeTree": ("I", "the node tree type, not a node"),
    "ShaderNodeCustomGroup": ("I", "a base class for add-ons' own groups, not a node"),
    **{n: ("M", T_EXPORT + "test_node_trees_flatten_to_lambert_ggx") for n in
       "ShaderNodeAddShader ShaderNodeMixShader ShaderNodeBsdfDiffuse ShaderNodeBsdfAnisotropic ShaderNodeBsdfGlossy "
       "ShaderNodeBsdfPrincipled ShaderNodeEmission ShaderNodeOutputMaterial".split()},
    **{n: ("M", "test_addon_glass.py::test_glass_refraction_and_transparent_shaders_export_as_blender_defines_them")
       for n in "ShaderNodeBsdfGlass ShaderNodeBsdfRefraction ShaderNodeBsdfTransparent".split()},
    "ShaderNodeBsdfTranslucent": ("M", "test_addon_glass.py::test_a_translucent_curtain_lets_an_area_lamps_light_"
                                       "through_as_in_cycles"),
    **{n: ("M", T_EXPORT + "test_world_is_evaluated_by_blender_in_the_cores_layout") for n in
       "ShaderNodeBackground ShaderNodeOutputWorld ShaderNodeTexEnvironment ShaderNodeTexSky".split()},
    **{n: ("M", T_LIGHTS + "test_a_lights_node_tree_scales_its_emission_as_in_cycles") for n in
       "ShaderNodeOutputLight ShaderNodeLightFalloff".split()},
    "ShaderNodeTexImage": ("M", T_MATS + "test_a_byte_srgb_checker_on_base_color_matches_cycles"),
    "ShaderNodeValToRGB": ("M", T_MATS + "test_a_color_ramp_on_an_image_drives_the_albedo_as_in_cycles"),
    "ShaderNodeVertexColor": ("M", "test_addon_bake.py::test_color_attribute_on_the_albedo_follows_the_mesh_like_cycles"),
    **{n: ("M", T_MATS + "test_normal_and_bump_maps_shade_the_plane_as_in_cycles") for n in
       "ShaderNodeNormalMap ShaderNodeBump".split()},
    **{n: _GRAPH for n in
       "ShaderNodeMath ShaderNodeVectorMath ShaderNodeMix ShaderNodeMixRGB ShaderNodeHueSaturation "
       "ShaderNodeBrightContrast ShaderNodeGamma ShaderNodeInvert ShaderNodeSeparateColor ShaderNodeCombineColor "
       "ShaderNodeSeparateXYZ ShaderNodeCombineXYZ ShaderNodeSeparateRGB ShaderNodeCombineRGB ShaderNodeSeparateHSV "
       "ShaderNodeCombineHSV ShaderNodeRGB ShaderNodeValue ShaderNodeRGBCurve ShaderNodeFloatCurve "
       "ShaderNodeVectorCurve ShaderNodeMapRange ShaderNodeClamp ShaderNodeRGBToBW ShaderNodeBlackbody "
       "ShaderNodeWavelength".split()},
    **{n: _ON_OBJECT for n in
       "ShaderNodeTexNoise ShaderNodeTexVoronoi ShaderNodeTexWave ShaderNodeTexMagic ShaderNodeTexGradient "
       "ShaderNodeTexChecker ShaderNodeTexBrick ShaderNodeTexMusgrave ShaderNodeTexWhiteNoise ShaderNodeTexGabor "
       "ShaderNodeTexCoord ShaderNodeMapping ShaderNodeObjectInfo ShaderNodeVectorRotate ShaderNodeUVMap".split()},
    **{n: _NOT_EVALUATED for n in
       "ShaderNodeGroup ShaderNodeFresnel ShaderNodeLayerWeight ShaderNodeLightPath ShaderNodeNewGeometry "
       "ShaderNodeCameraData ShaderNodeAttribute ShaderNodeAmbientOcclusion ShaderNodeBevel ShaderNodeHairInfo "
       "ShaderNodeParticleInfo ShaderNodePointInfo ShaderNodeTangent ShaderNodeWireframe ShaderNodeVolumeInfo "
       "ShaderNodeNormal ShaderNodeVectorTransform ShaderNodeTexPointDensity ShaderNodeRadialTiling "
       "ShaderNodeSqueeze ShaderNodeLightInfo ShaderNodeRaycast ShaderNodeShadowRaycast ShaderNodeLightAccumulation "
       "ShaderNodeLightEvaluation ShaderNodeLightIterInternalInput ShaderNodeLightIterInternalOutput".split()},
    "ShaderNodeTexIES": ("M", T_LIGHTS + "test_an_ies_profile_shapes_a_lamps_light_as_in_cycles"),
    **{n: _UNSUPPORTED for n in
       "ShaderNodeBsdfHair ShaderNodeBsdfHairPrincipled ShaderNodeBsdfRayPortal ShaderNodeBsdfSheen ShaderNodeBsdfToon "
       "ShaderNodeBsdfMetallic ShaderNodeBsdfVelvet ShaderNodeEeveeSpecular ShaderNodeHoldout "
       "ShaderNodeSubsurfaceScattering ShaderNodeShaderToRGB ShaderNodeScript".split()},
    **{n: _VOLUME for n in
       "ShaderNodeVolumeAbsorption ShaderNodeVolumeScatter ShaderNodeVolumePrincipled ShaderNodeVolumeCoefficients"
       .split()},
    **{n: ("W", "the surface alone is") for n in
       "ShaderNodeDisplacement ShaderNodeVectorDisplacement".split()},
    **{n: ("I", "Freestyle line styles (Freestyle is warned)") for n in
       "ShaderNodeOutputLineStyle ShaderNodeUVAlongStroke".split()},
    "ShaderNodeOutputAOV": ("I", PASSES),
}
