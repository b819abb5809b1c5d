//! Loader, instance and the validation messenger.

use std::ffi::{c_void, CStr};
use std::sync::{Arc, Mutex};

use ash::vk;

use crate::error::{LoaderFault, Result, VkError};

pub(crate) const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";
/// The highest API version motu asks for; ash 0.38 knows Vulkan 1.3.
pub(crate) const TARGET_API_VERSION: u32 = vk::API_VERSION_1_3;
/// Environment variable forcing validation on (`1`) or off (`0`).
pub const ENV_VALIDATION: &str = "MOTU_VALIDATION";

/// Whether to enable `VK_LAYER_KHRONOS_validation`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ValidationRequest {
    /// Off unless `MOTU_VALIDATION=1` (then [`ValidationRequest::Required`]); the default for
    /// the CLI, since the layer costs time.
    #[default]
    FromEnv,
    /// On when the layer is installed, else off with a warning.
    Preferred,
    /// On; an error if the layer is missing.
    Required,
    Off,
}

impl ValidationRequest {
    pub(crate) fn resolve(self) -> Result<Self> {
        if self != Self::FromEnv {
            return Ok(self);
        }
        match std::env::var(ENV_VALIDATION).ok().as_deref().map(str::trim) {
            None | Some("") | Some("0") => Ok(Self::Off),
            Some("1") => Ok(Self::Required),
            Some(other) => Err(VkError::InvalidEnv {
                name: ENV_VALIDATION,
                value: other.to_string(),
                reason: "expected 0 or 1".into(),
            }),
        }
    }
}

/// Messages the validation layer reported. Errors fail tests and `check_validation`; warnings
/// of the VALIDATION type count as errors too (they flag spec misuse, e.g. a missing usage bit),
/// while performance warnings and info/verbose messages are only logged.
#[derive(Debug, Default)]
pub(crate) struct ValidationLog {
    pub(crate) errors: Mutex<Vec<String>>,
    pub(crate) warnings: Mutex<Vec<String>>,
}

impl ValidationLog {
    fn push(&self, list: &Mutex<Vec<String>>, msg: String) {
        // A poisoned lock only means another thread panicked while pushing; keep the data.
        let mut guard = list.lock().unwrap_or_else(|e| e.into_inner());
        if guard.len() < 10_000 {
            guard.push(msg);
        }
    }
    pub(crate) fn errors(&self) -> Vec<String> {
        self.errors
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }
    pub(crate) fn warnings(&self) -> Vec<String> {
        self.warnings
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }
}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the layer passes a valid callback-data pointer (or null) for the call's duration.
    let message = unsafe { data.as_ref() }
        // SAFETY: `p_message` is null or a NUL-terminated string owned by the layer.
        .and_then(|d| unsafe { d.message_as_c_str() })
        .map(|m| m.to_string_lossy().into_owned())
        .unwrap_or_else(|| "<no message>".into());
    // SAFETY: `user` is `Arc::as_ptr` of the ValidationLog that `InstanceShared` keeps alive
    // until after the messenger (and the instance) are destroyed.
    let log = unsafe { (user as *const ValidationLog).as_ref() };
    let is_validation = types.contains(vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION);
    if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR) {
        tracing::error!(target: "vulkan", "{message}");
        if let Some(log) = log {
            log.push(&log.errors, message);
        }
    } else if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::WARNING) {
        tracing::warn!(target: "vulkan", "{message}");
        if let Some(log) = log {
            if is_validation {
                log.push(&log.errors, format!("(validation warning) {message}"));
            } else {
                log.push(&log.warnings, message);
            }
        }
    } else {
        tracing::debug!(target: "vulkan", "{message}");
    }
    vk::FALSE
}

/// The loader, the instance and (when validation is on) the messenger. Destroyed last.
pub(crate) struct InstanceShared {
    /// Keeps the loader library loaded for as long as any handle exists (and creates surfaces).
    pub(crate) entry: ash::Entry,
    pub(crate) instance: ash::Instance,
    pub(crate) api_version: u32,
    debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    pub(crate) validation_enabled: bool,
    pub(crate) log: Arc<ValidationLog>,
}

impl InstanceShared {
    /// Whether VK_EXT_debug_utils is enabled (object names then show in validation messages).
    pub(crate) fn has_debug_utils(&self) -> bool {
        self.debug.is_some()
    }
}

impl InstanceShared {
    pub(crate) fn new(validation: ValidationRequest) -> Result<Self> {
        Self::with_extensions(validation, &[])
    }

    /// An instance that also enables `extra` (e.g. the window-system surface extensions).
    pub(crate) fn with_extensions(
        validation: ValidationRequest,
        extra: &[*const std::ffi::c_char],
    ) -> Result<Self> {
        let validation = validation.resolve()?;
        // SAFETY: loading libvulkan runs its initialisers; we trust the system loader.
        let entry = unsafe { ash::Entry::load() }
            .map_err(|e| VkError::LoaderMissing { reason: e.into() })?;
        // SAFETY: entry is a loaded loader; this global command has no preconditions.
        let loader_version = unsafe { entry.try_enumerate_instance_version() }
            .map_err(VkError::vk("vkEnumerateInstanceVersion"))?
            .unwrap_or(vk::API_VERSION_1_0);
        let api_version = loader_version.min(TARGET_API_VERSION);
        if api_version < vk::API_VERSION_1_2 {
            return Err(VkError::LoaderMissing {
                reason: LoaderFault::TooOld(version_string(loader_version)),
            });
        }

        // SAFETY: global command on a loaded entry.
        let layers = unsafe { entry.enumerate_instance_layer_properties() }
            .map_err(VkError::vk("vkEnumerateInstanceLayerProperties"))?;
        let has_layer = layers
            .iter()
            .any(|l| l.layer_name_as_c_str().is_ok_and(|n| n == VALIDATION_LAYER));
        // SAFETY: global command on a loaded entry; `None` asks for the implementation's list.
        let extensions = unsafe { entry.enumerate_instance_extension_properties(None) }
            .map_err(VkError::vk("vkEnumerateInstanceExtensionProperties"))?;
        let has_ext = |name: &CStr| {
            extensions
                .iter()
                .any(|e| e.extension_name_as_c_str().is_ok_and(|n| n == name))
        };
        let has_debug_utils = has_ext(ash::ext::debug_utils::NAME);

        let validation_enabled = match validation {
            ValidationRequest::Required if !has_layer => {
                return Err(VkError::ValidationLayerMissing)
            }
            ValidationRequest::Required => true,
            ValidationRequest::Preferred if !has_layer => {
                tracing::warn!("VK_LAYER_KHRONOS_validation not installed: validation is off");
                false
            }
            ValidationRequest::Preferred => true,
            ValidationRequest::Off | ValidationRequest::FromEnv => false,
        };
        let use_messenger = validation_enabled && has_debug_utils;
        if validation_enabled && !has_debug_utils {
            return Err(VkError::MissingFeature {
                what: "VK_EXT_debug_utils (needed to collect validation messages)".into(),
                details: "the instance does not expose it".into(),
            });
        }

        let mut layer_names = Vec::new();
        if validation_enabled {
            layer_names.push(VALIDATION_LAYER.as_ptr());
        }
        let mut ext_names = Vec::new();
        if use_messenger {
            ext_names.push(ash::ext::debug_utils::NAME.as_ptr());
        }
        ext_names.extend_from_slice(extra);

        let log = Arc::new(ValidationLog::default());
        let app = vk::ApplicationInfo::default()
            .application_name(c"motu")
            .engine_name(c"motu")
            .api_version(api_version);
        let mut messenger_info = vk::DebugUtilsMessengerCreateInfoEXT::default()
            .message_severity(
                vk::DebugUtilsMessageSeverityFlagsEXT::ERROR
                    | vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                    | vk::DebugUtilsMessageSeverityFlagsEXT::INFO,
            )
            .message_type(
                vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                    | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                    | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
            )
            .pfn_user_callback(Some(debug_callback))
            .user_data(Arc::as_ptr(&log) as *mut c_void);
        let mut create_info = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layer_names)
            .enabled_extension_names(&ext_names);
        if use_messenger {
            // Also catches messages from vkCreateInstance/vkDestroyInstance themselves.
            create_info = create_info.push_next(&mut messenger_info);
        }
        // SAFETY: create_info and everything it points to (names, app info, messenger info with
        // a user-data pointer into `log`, which outlives the instance) are valid for the call.
        let instance = unsafe { entry.create_instance(&create_info, None) }.map_err(|e| {
            if e == vk::Result::ERROR_INCOMPATIBLE_DRIVER {
                // The loader's way of saying it found no driver (ICD) at all.
                VkError::NoDevice
            } else {
                VkError::Vulkan {
                    call: "vkCreateInstance",
                    result: e,
                }
            }
        })?;

        let debug = if use_messenger {
            let du = ash::ext::debug_utils::Instance::new(&entry, &instance);
            // SAFETY: the instance enabled VK_EXT_debug_utils; the info is valid (see above).
            match unsafe { du.create_debug_utils_messenger(&messenger_info, None) } {
                Ok(m) => Some((du, m)),
                Err(e) => {
                    // SAFETY: nothing else was created from this instance yet.
                    unsafe { instance.destroy_instance(None) };
                    return Err(VkError::Vulkan {
                        call: "vkCreateDebugUtilsMessengerEXT",
                        result: e,
                    });
                }
            }
        } else {
            None
        };
        tracing::debug!(
            api = %version_string(api_version),
            validation = validation_enabled,
            "Vulkan instance created"
        );
        Ok(Self {
            entry,
            instance,
            api_version,
            debug,
            validation_enabled,
            log,
        })
    }
}

impl Drop for InstanceShared {
    fn drop(&mut self) {
        if let Some((du, messenger)) = self.debug.take() {
            // SAFETY: the messenger was created from this instance and is destroyed once.
            unsafe { du.destroy_debug_utils_messenger(messenger, None) };
        }
        // SAFETY: every child object (devices, messenger) was destroyed before this runs:
        // `DeviceShared` owns the instance and destroys its device first.
        unsafe { self.instance.destroy_instance(None) };
        // `entry` (the loader library) is dropped after this, as a field.
    }
}

pub(crate) fn version_string(v: u32) -> String {
    format!(
        "{}.{}.{}",
        vk::api_version_major(v),
        vk::api_version_minor(v),
        vk::api_version_patch(v)
    )
}
